"""`rad eval --workers N`: an evaluation's scenes fanned out over Dask distributed workers.

Each scene is one task, and its row is the one `evaluation.evaluate` would report for it:
scene i runs `scene_episode` with seed + i whichever worker gets it, and the rows are put
back in scene order before `summarize`, so a distributed run gives the serial run's rows
and metrics (only wall-clock fields such as `reallocation_s` differ, as between two serial
runs). Two things outside this module can make rows differ between any two runs, serial or
not: anytime planning (verified agents with a search or with order repair, the `default` preset
among them) improves its first plan within a wall-clock budget (`agent_plan.IMPROVE_TIME_S`), so
on a busier machine a search or a repair plan can be cut where it finished before; and a
network's scores can differ in the last bits with torch's thread count (the workers run one
thread, a serial run torch's default, the cores), enough to flip a near tie. Agents without both
(heur, heur-norobot, unverified ones) are exact.

Tasks carry arguments, not objects: the agent as `AgentArgs` (what `get_agent` needs),
the scene as its `Scene.to_dict()` document, the CP-SAT and re-allocation settings as
plain dicts. So a task means the same on any worker, one rad starts here or one of a
scheduler elsewhere running the same rad. What is expensive to build (the policy, a
Q-network; the PyBullet client of the no-robot stability check; with the robot, the agent's
planner with its GAMP and planning-twin worlds) each worker thread builds once and keeps for
the scenes it gets (`_worker_state`).

Workers warm once, at start-up, not per task. The cluster `rad eval --workers N` starts
(`evaluate_distributed`: `dask_client(workers=N, start_method=START_METHOD)`; other callers
of `dask_client`, such as `rad train --actors`, keep Dask's spawn) forks its workers from this
process on Linux, so they
begin with what it has imported (torch, OR-Tools, PyBullet, rad) instead of importing it all
again (4-5 s of one core each: docs/results/distributed.md); each sets torch to one
thread before anything runs (`dask_setup`: a process forked after torch ran on several threads
would hang in OpenMP otherwise). `evaluate_distributed` then registers `WarmUp`, a worker plugin
that builds the agent, its policy and the planner's worlds (or the stability check) on every
worker before the first scene is sent, and again on any worker that joins later (a nanny's
replacement). Scenes are sent longest first (`scene_cost`: blocks and target cells), so the
workers finish together instead of one waiting on a big scene sent last; a worker holds one
scene at a time (worker-saturation 1.0), so none waits behind another's queue at the end.

A worker that dies takes its running and finished-but-not-gathered tasks with it; the
scheduler runs them again elsewhere (its `distributed.scheduler.allowed-failures`, default
3 deaths per task, before it gives up with KilledWorker). Tasks are pure (same arguments,
same row; nothing written anywhere), so a rerun changes nothing, and rows are keyed by
scene index, so none is lost or counted twice.

The cluster rad starts binds its scheduler, nannies and workers to 127.0.0.1 only and has
no dashboard unless asked for, then on 127.0.0.1 too. Code that starts one must sit under
`if __name__ == '__main__':` (where workers are spawned, they import the main module).
"""

from __future__ import annotations

import asyncio
import dataclasses
import importlib.util
import json
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from distributed.diagnostics.plugin import WorkerPlugin

from rad_core.allocation import AllocationParams
from rad_core.domain.errors import RadError
from rad_core.domain.scene import Scene
from rad_core.experiment.evaluation import get_agent, robot_planner, scene_episode, summarize, uses_robot
from rad_core.sequencing.planning.reallocation import ReallocationConfig
from rad_core.sim.physics import PhysicsStability

LOOPBACK = '127.0.0.1'
DASHBOARD_ADDRESS = f'{LOOPBACK}:8787'
CONNECT_TIMEOUT_S = 5.0
"""How long connecting to a --scheduler may take before it counts as unreachable."""
WAIT_WORKERS_S = 60.0
"""How long to wait for a --scheduler's cluster to have the workers asked for."""
START_METHOD = 'fork' if sys.platform.startswith('linux') else 'spawn'
"""How the cluster rad starts makes its worker processes: forked from this (already warm)
process where that is safe (Linux), else spawned (fresh interpreters that import everything)."""


@dataclass(frozen=True)
class AgentArgs:
    """The arguments of `evaluation.get_agent`: plain data a worker rebuilds the agent from,
    and the key under which it keeps the built policy."""

    agent: str
    checkpoint: str | None = None
    verify: bool = False
    budget: int | None = None
    reallocate: bool = False

    def build(self):
        return get_agent(self.agent, self.checkpoint, self.verify, self.budget, self.reallocate)

    def portable(self) -> 'AgentArgs':
        """The same, with a checkpoint file given by its absolute path (workers may run
        in another directory)."""
        if self.checkpoint is not None and Path(self.checkpoint).is_file():
            return dataclasses.replace(self, checkpoint=str(Path(self.checkpoint).resolve()))
        return self


# ---- the worker side -------------------------------------------------------------
_local = threading.local()


def dask_setup(worker=None) -> None:
    """Worker preload of the cluster rad starts (run in the new worker process before any task):
    torch on one thread, as Dask's OMP_NUM_THREADS=1 gives spawned workers. A forked worker
    inherits torch already initialized, where the variable no longer counts, and torch on
    several threads in a process forked after its parent ran OpenMP threads hangs."""
    torch = sys.modules.get('torch')
    if torch is not None:
        torch.set_num_threads(1)


def _worker_state() -> dict:
    """This worker thread's built agents and policies ({AgentArgs: (agent, policy)}) and its
    no-robot stability check. Per thread, not per process: a PyBullet client is not
    thread-safe, and a scheduler elsewhere may run several threads per worker (rad's own
    cluster runs one, so this is once per worker process). Its first call puts torch on one
    thread, as a Dask worker's OMP_NUM_THREADS=1 does."""
    state = getattr(_local, 'state', None)
    if state is None:
        dask_setup()   # this thread too: torch's thread count is per thread under OpenMP
        state = _local.state = {'agents': {}, 'stability': None}
    return state


def _agent_and_policy(args: AgentArgs):
    agents = _worker_state()['agents']
    if args not in agents:
        agent = args.build()
        agents[args] = (agent, agent.make_policy())
    return agents[args]


def _planner(args: AgentArgs, allocation: dict | None, reallocation: dict | None):
    """This worker thread's robot planner for the agent and settings (`evaluation.robot_planner`:
    the network, GAMP's world and the sequencer's planning twin), built once and kept."""
    planners = _worker_state().setdefault('planners', {})
    key = (args, json.dumps(allocation, sort_keys=True), json.dumps(reallocation, sort_keys=True))
    if key not in planners:
        planners[key] = robot_planner(_agent_and_policy(args)[0], _allocation_params(allocation),
                                      _reallocation_config(reallocation))
    return planners[key]


def _stability():
    state = _worker_state()
    if state['stability'] is None:
        state['stability'] = PhysicsStability()
    return state['stability']


def _allocation_params(doc: dict | None):
    if doc is None:
        return None
    return AllocationParams(**doc)


def _reallocation_config(doc: dict | None):
    if doc is None:
        return None
    return ReallocationConfig(**{**doc, 'params': _allocation_params(doc['params'])})


def warm(agent_args: AgentArgs, robot: bool, allocation: dict | None = None,
         reallocation: dict | None = None) -> float:
    """Build in this worker thread what `run_scene` needs for the agent and settings (the agent,
    its policy, with the robot the planner and its worlds, else the stability check) and keep
    it; return the seconds it took (0 when it was built already)."""

    t0 = time.perf_counter()
    agent, _ = _agent_and_policy(agent_args)
    if uses_robot(agent, robot):
        _planner(agent_args, allocation, reallocation)
    else:
        _stability()
    return time.perf_counter() - t0


class WarmUp(WorkerPlugin):
    """A Dask worker plugin: `warm` on every worker of the cluster, now and on any that joins
    later, in the thread pool that runs its tasks (so the scenes find everything built).
    Idempotent under its name, which the agent and settings determine: registering the same
    again on a cluster that has it does nothing."""

    idempotent = True

    def __init__(self, agent_args: AgentArgs, robot: bool, allocation: dict | None = None,
                 reallocation: dict | None = None):
        self.agent_args, self.robot, self.allocation, self.reallocation = agent_args, robot, allocation, reallocation
        doc = json.dumps([dataclasses.asdict(agent_args), robot, allocation, reallocation], sort_keys=True)
        self.name = f'rad-warm-up-{uuid.uuid5(uuid.NAMESPACE_OID, doc).hex[:12]}'

    async def setup(self, worker) -> None:
        executor = worker.executors.get('default')
        if executor is None:   # no thread pool to warm: the first scenes warm it
            return
        # One thread: all of a worker of rad's cluster; on a worker with more, the others warm
        # on their first scene.
        await asyncio.get_running_loop().run_in_executor(
            executor, warm, self.agent_args, self.robot, self.allocation, self.reallocation)


def warm_up(client, agent_args: AgentArgs, robot: bool, allocation: dict | None = None,
            reallocation: dict | None = None) -> str:
    """Register `WarmUp` on the client's cluster and return once every worker is warm; return
    the plugin's name (`client.unregister_worker_plugin(name)` stops warming workers that join
    later; what is built stays)."""
    plugin = WarmUp(agent_args.portable(), robot, allocation, reallocation)
    client.register_plugin(plugin, name=plugin.name)
    return plugin.name


def run_scene(name: str, scene_doc: dict, agent_args: AgentArgs, robot: bool, seed: int, execution: str,
              allocation: dict | None = None, reallocation: dict | None = None) -> dict:
    """One scene's row, exactly as `evaluation.evaluate` makes it (the task every worker runs)."""
    try:
        agent, policy = _agent_and_policy(agent_args)
        with_robot = uses_robot(agent, robot)
        stability = None if with_robot else _stability()
        planner = _planner(agent_args, allocation, reallocation) if with_robot else None
        row = scene_episode(agent, Scene.from_dict(scene_doc), robot, seed, execution, policy,
                            allocation=_allocation_params(allocation), stability=stability,
                            reallocation=_reallocation_config(reallocation), planner=planner)
    except RadError as e:
        # Subclasses with their own __init__ (SceneError) do not survive pickling back.
        raise RadError(str(e)) from None
    return {'name': name, **row}


# ---- the client side -------------------------------------------------------------
# A local worker's own upkeep, made rare: each of these wakes the worker's event loop in the
# process that runs the scenes, and every wake-up takes the GIL from the scene's thread (Dask's
# defaults: the loop's health check every 20 ms, the statistical profiler sampling the task
# thread every 10 ms, psutil every 500 ms, the memory check every 100 ms). Two workers on 40
# scenes, alternating with and without: 18.8 / 18.1 s against 19.8 / 19.6 s, 5 % less CPU
# (docs/results/distributed.md). With --dashboard the profiler stays on for its profile page.
QUIET_WORKER = {'distributed.admin.tick.interval': '1s', 'distributed.worker.profile.enabled': False,
                'distributed.admin.system-monitor.interval': '5s',
                'distributed.worker.memory.monitor-interval': '1s'}


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None, dashboard: bool = False,
                connect_timeout_s: float = CONNECT_TIMEOUT_S, wait_workers_s: float = WAIT_WORKERS_S,
                start_method: str | None = None) -> Iterator:
    """A `distributed.Client`, closed (with the cluster rad started) on exit.

    Without scheduler: a LocalCluster of `workers` processes with one thread each, all on
    127.0.0.1, the dashboard off unless `dashboard` (then on 127.0.0.1:8787; it needs bokeh).
    start_method: how its worker processes start, 'fork' (from this process: what it has
    imported comes free; `START_METHOD`, what `evaluate_distributed` asks for), 'spawn' or
    'forkserver'; default Dask's (spawn). Each worker holds one task at a time
    (worker-saturation 1.0: with tasks of seconds, the scheduler's queue balances best) and
    runs `dask_setup` first.
    With scheduler (an address such as tcp://127.0.0.1:8786): a client of that scheduler;
    `workers` is then the least number of workers to wait for (default 1), at most
    wait_workers_s. An address that does not answer within connect_timeout_s is a RadError.
    """
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise RadError(f'--workers must be a whole number of at least 1, got {workers!r}')
    if scheduler is not None and not scheduler.strip():
        raise RadError('--scheduler needs an address, e.g. tcp://127.0.0.1:8786')
    if scheduler is None and workers is None:
        raise RadError('give --workers N (a local cluster) or --scheduler ADDR (an existing one)')
    from distributed import Client, LocalCluster  # dask: only a scale-out run pays for its import
    if scheduler is not None:
        if dashboard:
            raise RadError('--dashboard applies to the cluster rad starts, not to an existing --scheduler')
        _probe_scheduler(scheduler, connect_timeout_s)
        try:
            client = Client(scheduler, timeout=connect_timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as e:
            raise RadError(f'cannot reach the Dask scheduler at {scheduler!r} within {connect_timeout_s:g} s '
                           f'({_one_line(e)})') from None
        try:
            need = workers or 1
            try:
                client.wait_for_workers(need, timeout=wait_workers_s)
            except TimeoutError:
                # (nthreads asks the scheduler; scheduler_info's answer can be overwritten by the client's
                # periodic update, which carries no workers, before it is returned: distributed 2026.8)
                have = len(client.nthreads())
                raise RadError(f'the Dask scheduler at {scheduler!r} has {have} worker(s); waited '
                               f'{wait_workers_s:g} s for {need}') from None
            yield client
        finally:
            client.close()
        return
    if dashboard and importlib.util.find_spec('bokeh') is None:
        raise RadError('--dashboard needs bokeh (pip install bokeh), or run without --dashboard')
    if start_method not in (None, 'fork', 'spawn', 'forkserver'):
        raise RadError(f"start_method must be 'fork', 'spawn' or 'forkserver', got {start_method!r}")
    import dask  # dask: only a scale-out run pays for its import
    config = {'distributed.scheduler.worker-saturation': 1.0, 'distributed.worker.preload': [__name__],
              **QUIET_WORKER}
    if dashboard:
        config['distributed.worker.profile.enabled'] = True     # the dashboard's profile page needs it
    if start_method is not None:
        config['distributed.worker.multiprocessing-method'] = start_method
    # Kept for the whole run: a nanny that restarts its worker reads the method again.
    with dask.config.set(config), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host=LOOPBACK,
                         dashboard_address=DASHBOARD_ADDRESS if dashboard else None) as cluster, \
            Client(cluster, set_as_default=False) as client:
        client.wait_for_workers(workers, timeout=wait_workers_s)
        if dashboard:
            print(f'rad: Dask dashboard at {client.dashboard_link}', file=sys.stderr)
        yield client


def _probe_scheduler(address: str, timeout_s: float) -> None:
    """Ask `address` who it is, all within timeout_s, or raise a RadError.

    `Client(address, timeout=...)` alone is not enough: its timeout covers the TCP connect
    but not Dask's handshake after it (distributed 2026.8), so a peer that accepts the
    connection and never answers would hang it for good."""

    from distributed.comm import connect  # dask: only a scale-out run pays for its import

    async def identity() -> dict:
        comm = await connect(address, timeout=timeout_s)
        try:
            await comm.write({'op': 'identity', 'reply': True})
            return await comm.read()
        finally:
            comm.abort()

    problem = ''
    try:
        reply = asyncio.run(asyncio.wait_for(identity(), timeout_s))
    except (asyncio.TimeoutError, TimeoutError):
        problem = 'no answer'
    except (OSError, ValueError, TypeError) as e:
        problem = _one_line(e)
    else:
        if not (isinstance(reply, dict) and reply.get('type') == 'Scheduler'):
            kind = reply.get('type') if isinstance(reply, dict) else type(reply).__name__
            problem = f'it answered as {kind!r}, not as a scheduler'
    if problem:
        raise RadError(f'cannot reach the Dask scheduler at {address!r} within {timeout_s:g} s ({problem})')


def _one_line(error: BaseException) -> str:
    text = ' '.join(str(error).split()) or type(error).__name__
    return text if len(text) <= 200 else text[:197] + '...'


def evaluate_distributed(agent_args: AgentArgs, scenes: Iterable[tuple[str, Scene]], robot: bool, seed: int,
                         progress: Callable[[dict], None] | None = None, workers: int | None = None,
                         scheduler: str | None = None, execution: str = 'teleport', allocation=None,
                         reallocation=None, dashboard: bool = False, client=None, policy=None,
                         retries: int = 0, start_method: str | None = START_METHOD) -> dict:
    """`evaluation.evaluate` with one Dask task per scene; the same result for the same seeds.

    The cluster: `client` if given (left open), else `dask_client(workers, scheduler,
    dashboard, start_method=start_method)` for the duration of the run (its start-up
    forks the workers from this process, which has built the agent already: see the module
    docstring). Every worker is warm (`warm_up`) before the first scene is sent, and the
    scenes go out longest first (`scene_cost`). progress(row) is called as rows come back
    (completion order); the result's rows are in scene order. allocation, reallocation:
    an `AllocationParams` / `ReallocationConfig` (default: the agent's / its defaults).
    policy: an already built policy, only checked here against the agent's action space
    (each worker builds its own). retries: reruns of a task that raised; 0 because an
    episode is deterministic and would raise again (worker deaths are the scheduler's
    business, see the module docstring).
    """
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise RadError(f'--workers must be a whole number of at least 1, got {workers!r}')
    agent_args = agent_args.portable()
    agent = agent_args.build()
    policy = policy if policy is not None else agent.make_policy()
    trained_on = getattr(policy, 'actions', agent.actions)
    if trained_on != agent.actions:
        raise RadError(f'{getattr(policy, "source", agent.name)} was trained on the {trained_on!r} action space; '
                       f'agent {agent.name!r} chooses among {agent.actions!r} (pick the agent of that method)')
    scenes = list(scenes)
    if not scenes:
        raise RadError('no scenes to evaluate')
    alloc_doc = dataclasses.asdict(allocation) if allocation is not None else None
    realloc_doc = dataclasses.asdict(reallocation) if reallocation is not None else None
    if client is not None:
        rows = _run(client, agent_args, scenes, robot, seed, progress, execution, alloc_doc, realloc_doc, retries)
    else:
        with dask_client(workers, scheduler, dashboard, start_method=start_method) as own:
            rows = _run(own, agent_args, scenes, robot, seed, progress, execution, alloc_doc, realloc_doc, retries)
    return summarize(rows, agent.name)


def scene_cost(scene: Scene) -> int:
    """A scene's expected evaluation time, as a rank only: its blocks times its target cells
    (the allocation's size, and the steps the sequencer plans, each over the candidates left)."""
    cells = sum(len(t.filled) for t in scene.targets)
    return len(scene.blocks) * max(cells, 1)


def _run(client, agent_args, scenes, robot, seed, progress, execution, alloc_doc, realloc_doc, retries) -> list:
    """Warm every worker, submit one task per scene (the costliest first), collect the rows as
    they finish, return them in scene order."""
    from distributed import as_completed  # dask: only a scale-out run pays for its import
    from distributed.scheduler import KilledWorker  # dask: only a scale-out run pays for its import
    try:
        plugin = warm_up(client, agent_args, robot, alloc_doc, realloc_doc)
    except RadError as e:
        raise RadError(f'warming the workers up: {e}') from None
    run = uuid.uuid4().hex[:12]   # explicit keys: unique per run, one per scene index
    index = {}
    costs = [scene_cost(scene) for _, scene in scenes]
    # Longest first, so the workers finish together: submitted in that order (the first go out
    # as they arrive) and with that priority (the scheduler's queue hands out the highest first,
    # equal ones in submission order). A row does not depend on where or when it runs.
    for i in sorted(range(len(scenes)), key=lambda i: (-costs[i], i)):
        name, scene = scenes[i]
        future = client.submit(run_scene, name, scene.to_dict(), agent_args, robot, seed + i, execution,
                               alloc_doc, realloc_doc, key=f'rad-scene-{run}-{i:06d}', retries=retries,
                               priority=costs[i])
        index[future] = i
    rows: dict[int, dict] = {}
    try:
        for future in as_completed(list(index), loop=client.loop):
            i = index[future]
            name = scenes[i][0]
            try:
                row = future.result()
            except RadError as e:
                raise RadError(f'scene {name!r}: {e}') from None
            except KilledWorker as e:
                raise RadError(f'scene {name!r}: every worker that ran it died ({_one_line(e)})') from None
            if i in rows:
                continue
            rows[i] = row
            if progress is not None:
                progress(row)
    finally:
        pending = [f for f in index if not f.done()]
        if pending:
            client.cancel(pending)
        try:   # workers that join later need not warm up for this run; what is built stays
            client.unregister_worker_plugin(plugin)
        except Exception:   # noqa: BLE001 - tidying up only: a cluster gone or a worker lost
            pass
    missing = [scenes[i][0] for i in range(len(scenes)) if i not in rows]
    if missing:
        raise RadError(f'no result for scene(s) {", ".join(missing)}')
    return [rows[i] for i in range(len(scenes))]

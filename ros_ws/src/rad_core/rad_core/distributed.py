"""`rad eval --workers N`: an evaluation's scenes fanned out over Dask distributed workers.

Each scene is one task, and its row is the one `evaluation.evaluate` would report for it:
scene i runs `scene_episode` with seed + i whichever worker gets it, and the rows are put
back in scene order before `summarize`, so a distributed run gives the serial run's rows
and metrics (only wall-clock fields such as `reallocation_s` differ, as between two serial
runs).

Tasks carry arguments, not objects: the agent as `AgentArgs` (what `get_agent` needs),
the scene as its `Scene.to_dict()` document, the CP-SAT and re-allocation settings as
plain dicts. So a task means the same on any worker, one rad starts here or one of a
scheduler elsewhere running the same rad. What is expensive to build (the policy, a
Q-network; the PyBullet client of the no-robot stability check; with the robot, the agent's
planner with its GAMP and planning-twin worlds) each worker thread builds once and keeps for
the scenes it gets (`_worker_state`).

A worker that dies takes its running and finished-but-not-gathered tasks with it; the
scheduler runs them again elsewhere (its `distributed.scheduler.allowed-failures`, default
3 deaths per task, before it gives up with KilledWorker). Tasks are pure (same arguments,
same row; nothing written anywhere), so a rerun changes nothing, and rows are keyed by
scene index, so none is lost or counted twice.

The cluster rad starts binds its scheduler, nannies and workers to 127.0.0.1 only and has
no dashboard unless asked for, then on 127.0.0.1 too. Code that starts one must sit under
`if __name__ == '__main__':` (workers are spawned processes that import the main module).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
import threading
import uuid
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from rad_core.errors import RadError
from rad_core.scene import Scene

LOOPBACK = '127.0.0.1'
DASHBOARD_ADDRESS = f'{LOOPBACK}:8787'
CONNECT_TIMEOUT_S = 5.0
"""How long connecting to a --scheduler may take before it counts as unreachable."""
WAIT_WORKERS_S = 60.0
"""How long to wait for a --scheduler's cluster to have the workers asked for."""


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
        from rad_core.evaluation import get_agent
        return get_agent(self.agent, self.checkpoint, self.verify, self.budget, self.reallocate)

    def portable(self) -> 'AgentArgs':
        """The same, with a checkpoint file given by its absolute path (workers may run
        in another directory)."""
        if self.checkpoint is not None and Path(self.checkpoint).is_file():
            return dataclasses.replace(self, checkpoint=str(Path(self.checkpoint).resolve()))
        return self


# ---- the worker side -------------------------------------------------------------
_local = threading.local()


def _worker_state() -> dict:
    """This worker thread's built agents and policies ({AgentArgs: (agent, policy)}) and its
    no-robot stability check. Per thread, not per process: a PyBullet client is not
    thread-safe, and a scheduler elsewhere may run several threads per worker (rad's own
    cluster runs one, so this is once per worker process)."""
    state = getattr(_local, 'state', None)
    if state is None:
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
    import json
    planners = _worker_state().setdefault('planners', {})
    key = (args, json.dumps(allocation, sort_keys=True), json.dumps(reallocation, sort_keys=True))
    if key not in planners:
        from rad_core.evaluation import robot_planner
        planners[key] = robot_planner(_agent_and_policy(args)[0], _allocation_params(allocation),
                                      _reallocation_config(reallocation))
    return planners[key]


def _stability():
    state = _worker_state()
    if state['stability'] is None:
        from rad_core.physics import PhysicsStability
        state['stability'] = PhysicsStability()
    return state['stability']


def _allocation_params(doc: dict | None):
    if doc is None:
        return None
    from rad_core.allocation import AllocationParams
    return AllocationParams(**doc)


def _reallocation_config(doc: dict | None):
    if doc is None:
        return None
    from rad_core.sequencing.reallocation import ReallocationConfig
    return ReallocationConfig(**{**doc, 'params': _allocation_params(doc['params'])})


def run_scene(name: str, scene_doc: dict, agent_args: AgentArgs, robot: bool, seed: int, execution: str,
              allocation: dict | None = None, reallocation: dict | None = None) -> dict:
    """One scene's row, exactly as `evaluation.evaluate` makes it (the task every worker runs)."""
    from rad_core.evaluation import scene_episode, uses_robot
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
@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None, dashboard: bool = False,
                connect_timeout_s: float = CONNECT_TIMEOUT_S, wait_workers_s: float = WAIT_WORKERS_S) -> Iterator:
    """A `distributed.Client`, closed (with the cluster rad started) on exit.

    Without scheduler: a LocalCluster of `workers` processes with one thread each, all on
    127.0.0.1, the dashboard off unless `dashboard` (then on 127.0.0.1:8787; it needs bokeh).
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
    from distributed import Client, LocalCluster
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
                have = len(client.scheduler_info(n_workers=-1)['workers'])
                raise RadError(f'the Dask scheduler at {scheduler!r} has {have} worker(s); waited '
                               f'{wait_workers_s:g} s for {need}') from None
            yield client
        finally:
            client.close()
        return
    if dashboard and importlib.util.find_spec('bokeh') is None:
        raise RadError('--dashboard needs bokeh (pip install bokeh), or run without --dashboard')
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host=LOOPBACK,
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
    import asyncio

    from distributed.comm import connect

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
                         retries: int = 0) -> dict:
    """`evaluation.evaluate` with one Dask task per scene; the same result for the same seeds.

    The cluster: `client` if given (left open), else `dask_client(workers, scheduler,
    dashboard)` for the duration of the run. progress(row) is called as rows come back
    (completion order); the result's rows are in scene order. allocation, reallocation:
    an `AllocationParams` / `ReallocationConfig` (default: the agent's / its defaults).
    policy: an already built policy, only checked here against the agent's action space
    (each worker builds its own). retries: reruns of a task that raised; 0 because an
    episode is deterministic and would raise again (worker deaths are the scheduler's
    business, see the module docstring).
    """
    from rad_core.evaluation import summarize
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
        with dask_client(workers, scheduler, dashboard) as own:
            rows = _run(own, agent_args, scenes, robot, seed, progress, execution, alloc_doc, realloc_doc, retries)
    return summarize(rows, agent.name)


def _run(client, agent_args, scenes, robot, seed, progress, execution, alloc_doc, realloc_doc, retries) -> list:
    """Submit one task per scene, collect the rows as they finish, return them in scene order."""
    from distributed import as_completed
    from distributed.scheduler import KilledWorker
    run = uuid.uuid4().hex[:12]   # explicit keys: unique per run, one per scene index
    index = {}
    for i, (name, scene) in enumerate(scenes):
        future = client.submit(run_scene, name, scene.to_dict(), agent_args, robot, seed + i, execution,
                               alloc_doc, realloc_doc, key=f'rad-scene-{run}-{i:06d}', retries=retries)
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
    missing = [scenes[i][0] for i in range(len(scenes)) if i not in rows]
    if missing:
        raise RadError(f'no result for scene(s) {", ".join(missing)}')
    return [rows[i] for i in range(len(scenes))]

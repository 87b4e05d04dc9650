"""`rad train --actors N`: experience from Dask actors, one learner taking gradient steps.

How it works (read with `dqn.Trainer`, whose networks, replay, update, evaluation and
checkpoints the learner here reuses unchanged):

- An actor's work is a *rollout task* (`collect`): whole training episodes on scenes of
  the dataset until at least `chunk_steps` environment steps, epsilon-greedy with one
  published copy of the online network, returning the transitions. A task carries plain
  arguments (the TrainConfig as a dict, the task's seed, the epsilon to act with) and the
  weights as a Dask future; what is costly to build (the dataset, the Q-network, the
  PyBullet client) each worker thread builds once and keeps (`_actor_state`).
- N tasks are in flight at all times, one per actor. When one finishes, the learner puts
  its transitions into its replay (in the order they were played, so `next_obs` sharing
  holds) and submits the next task for that actor with the newest weights.
- Weight refresh: the learner *publishes* its online weights every `refresh_every`
  gradient steps: a versioned CPU state_dict scattered to the cluster once
  (`client.scatter`, broadcast to every worker), whose future every task submitted after it gets. A worker loads a
  version into its network only when it differs from the one it has. An actor therefore
  acts with weights at most `refresh_every` gradient steps plus one task old. Nothing is
  pushed into a running task; there is no shared mutable state, so a worker that dies just
  has its task rerun by the scheduler with the same arguments.
- The learner takes gradient steps whenever the replay ratio allows, i.e. while
  grad_steps < (env_steps - learning_starts) / train_every, and otherwise waits for the
  next finished task: `train_every` keeps its meaning (environment steps per gradient
  step), and a slow cluster does not make the learner overfit a small replay. The target
  network is updated every `target_update` environment steps, epsilon decays with the
  learner's environment steps, and evaluation and logs run as in the serial trainer.
- Checkpoints are the serial trainer's (`Trainer.save`, atomic), taken between tasks;
  `position` also counts the tasks submitted (`tasks`), so a resumed run seeds its tasks
  anew. Transitions of tasks in flight at a checkpoint are not in it; a resumed run
  simply collects new ones.

Not bit-deterministic: which task finishes first, and so the order of transitions in the
replay and the weights each task acts with, depends on timing. Each task's own rollout is
a function of its seed, epsilon and weights version. The serial `rad train` (no
--actors) is untouched and stays deterministic.

The robot in the loop (--robot) is not supported with actors yet (the step cache would
be per worker); it is refused.
"""

from __future__ import annotations

import signal
import threading
import time
import uuid
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from rad_core.domain.errors import RadError
from rad_core.env.mdp import AssemblyEnv, EnvConfig
from rad_core.experiment.distributed import dask_client
from rad_core.learning.network import QNetwork, collate, graph_max
from rad_core.learning.replay import Transition
from rad_core.sequencing.decide.actions import action_space
from rad_core.sim.physics import PhysicsStability
from rad_core.training.curves import plot_progress
from rad_core.training.dataset import Dataset
from rad_core.training.dqn import METHODS, TrainConfig, Trainer, explore, open_run, train


@dataclass
class ActorConfig:
    """How experience is collected with --actors (not part of TrainConfig: the serial run
    and its checkpoints stay as they are)."""

    actors: int = 2            # rollout tasks in flight, one per actor
    chunk_steps: int = 32      # environment steps an actor plays per task (whole episodes, at least this many)
    refresh_every: int = 10    # learner gradient steps between weight publications

    def validate(self) -> None:
        for name in ('actors', 'chunk_steps', 'refresh_every'):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                flag = '--' + name.replace('_', '-')
                raise RadError(f'{flag} must be a whole number of at least 1, got {value!r}')


# ---- the worker side -------------------------------------------------------------
_local = threading.local()


def _actor_state(config: dict) -> dict:
    """This worker thread's dataset, network and stability check for one training config."""
    key = repr(sorted(config.items()))
    states = getattr(_local, 'states', None)
    if states is None:
        states = _local.states = {}
    if key not in states:
        cfg = TrainConfig.from_dict(config)
        torch.set_num_threads(1)
        states[key] = {'cfg': cfg, 'dataset': Dataset.load(cfg.dataset), 'q': QNetwork(cfg.net).eval(),
                       'stability': PhysicsStability(), 'version': None}
    return states[key]


def collect(config: dict, weights: dict, seed: int, epsilon: float, chunk_steps: int) -> dict:
    """Whole epsilon-greedy episodes until at least chunk_steps steps: the task an actor runs.

    weights: {'run', 'version', 'state'} as the learner published them. Returns the
    transitions in play order, the episodes' (return, coverage) and the version used."""
    try:
        state = _actor_state(config)
        cfg, q = state['cfg'], state['q']
        tag = (weights['run'], weights['version'])
        if state['version'] != tag:
            q.load_state_dict(weights['state'])
            state['version'] = tag
        rng = np.random.default_rng(seed)
        actions_kind = METHODS[cfg.method]

        @torch.no_grad()
        def greedy(obs) -> int:
            batch = collate([obs], torch.device('cpu'))
            return int(graph_max(*q(batch), batch)[1][0])

        transitions: list[Transition] = []
        episodes: list[tuple[float, float]] = []
        while len(transitions) < chunk_steps:
            entry = state['dataset'].entries[int(rng.integers(len(state['dataset'])))]
            env = AssemblyEnv(entry.scene(), EnvConfig(stability='physics', gamma=cfg.gamma),
                              stability=state['stability'])
            ep = explore(env, action_space(actions_kind, env, entry.placements), rng, lambda: epsilon, greedy,
                         transitions.append)
            episodes.append((ep.ret, ep.coverage))
    except RadError as e:
        raise RadError(str(e)) from None   # subclasses with their own __init__ do not unpickle
    return {'transitions': transitions, 'episodes': episodes, 'version': weights['version']}


# ---- the learner -----------------------------------------------------------------
class DistributedTrainer(Trainer):
    """The serial trainer's networks, replay, update and checkpoints, fed by actors."""

    def __init__(self, cfg: TrainConfig, out: str | Path, actor: ActorConfig):
        if cfg.robot:
            raise RadError('--actors does not support --robot yet (train with the robot serially)')
        actor.validate()
        super().__init__(cfg, out)
        self.actor = actor
        self.pos.setdefault('tasks', 0)
        self.received = 0         # transitions put into the replay by actors in this process
        self.versions: list[tuple[int, int]] = []   # (learner's, task's) weights version of each finished task

    def run(self, progress=None, client=None) -> dict:
        if client is None:
            raise RadError('DistributedTrainer.run needs a Dask client')
        from distributed import as_completed  # dask: only a scale-out run pays for its import
        c, a = self.cfg, self.actor
        self.pos.setdefault('tasks', 0)
        self.out.mkdir(parents=True, exist_ok=True)
        config = asdict(c)
        config['dataset'] = str(Path(c.dataset).resolve()) if Path(c.dataset).exists() else c.dataset
        run_id = uuid.uuid4().hex[:12]
        version = 0
        published = self._publish(client, run_id, version)
        grads_at_publish = self.pos['grad_steps']
        t_start, last_ckpt = time.perf_counter() - self.pos['wall_s'], time.perf_counter()
        mark = (time.perf_counter(), self.pos['env_steps'], self.pos['grad_steps'])
        inflight: dict = {}
        finished = as_completed(loop=client.loop)   # the tasks, as they finish
        main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, self._on_sigint) if main else None
        interrupted = False

        def submit():
            n = self.pos['tasks']
            self.pos['tasks'] += 1
            seed = int(np.random.SeedSequence([c.seed, 7, n]).generate_state(1)[0])
            f = client.submit(collect, config, published, seed, self.epsilon(), a.chunk_steps,
                              key=f'rad-collect-{run_id}-{n:08d}', pure=False)
            inflight[f] = n
            finished.add(f)

        try:
            for _ in range(a.actors):
                submit()
            idle = False
            while self.pos['env_steps'] < c.total_steps:
                ready = finished.next_batch(block=False) if not idle else finished.next_batch(block=True)
                idle = False
                for f in ready:
                    del inflight[f]
                    self._receive(f, version)
                    submit()
                    mark = self._after_steps(t_start, mark, progress)
                    last_ckpt = self._checkpoint_due(last_ckpt)
                    if self.pos['env_steps'] >= c.total_steps:
                        break
                if self.pos['env_steps'] >= c.total_steps:
                    break
                if self._stop:   # SIGINT: checkpoint between updates, then stop
                    interrupted = True
                    break
                allowed = (self.pos['env_steps'] - c.learning_starts) // c.train_every + 1
                if self.pos['env_steps'] >= c.learning_starts and self.pos['grad_steps'] < allowed:
                    self.learn()
                    if self.pos['grad_steps'] - grads_at_publish >= a.refresh_every:
                        version += 1
                        published = self._publish(client, run_id, version)
                        grads_at_publish = self.pos['grad_steps']
                else:
                    idle = True   # nothing to learn from yet: block until a task finishes
            self.save()
        finally:
            if main:
                signal.signal(signal.SIGINT, previous)
            if inflight:
                client.cancel(list(inflight))
            if self._writer is not None:
                self._writer.close()
        if interrupted:
            return {'interrupted': True, **self.pos, 'received': self.received}
        plot_progress(self.out / 'progress.csv', self.out / 'curves.png',
                      title=f'{c.method} seed {c.seed}, {a.actors} actors')
        return {'interrupted': False, **self.pos, 'received': self.received}

    def _publish(self, client, run_id: str, version: int):
        state = {k: v.detach().to('cpu').clone() for k, v in self.q.state_dict().items()}
        # broadcast: a copy on every worker, so the scheduler places tasks by load, not by
        # where the weights happen to be. In a list: a scattered dict would be scattered
        # value by value under its own keys ('version', ...), the same keys every time.
        return client.scatter([{'run': run_id, 'version': version, 'state': state}], hash=False,
                              broadcast=True)[0]

    def _receive(self, future, version: int) -> None:
        from distributed.scheduler import KilledWorker  # dask: only a scale-out run pays for its import
        try:
            result = future.result()
        except KilledWorker as e:
            raise RadError(f'an actor task failed on every worker that ran it ({e})') from None
        before = self.pos['env_steps']
        for t in result['transitions']:
            self.replay.add(t)
        n = len(result['transitions'])
        self.received += n
        self.pos['env_steps'] += n
        self.pos['episodes'] += len(result['episodes'])
        self.recent = (self.recent + list(result['episodes']))[-100:]
        self.versions.append((version, result['version']))
        if self.pos['env_steps'] // self.cfg.target_update > before // self.cfg.target_update:
            self.target.load_state_dict(self.q.state_dict())


def train_with_actors(cfg: TrainConfig, out: str | Path, actor: ActorConfig, resume: bool = False,
                      total_steps: int | None = None, progress=None, scheduler: str | None = None,
                      client=None) -> dict:
    """`dqn.train` with experience from actors: a LocalCluster of `actor.actors` workers on
    127.0.0.1 unless `scheduler` (or an open `client`) is given. Same run folder, same
    checkpoint and model files; resume continues a serial or distributed checkpoint."""
    actor.validate()
    trainer = open_run(cfg, out, resume, total_steps, make=lambda c, o: DistributedTrainer(c, o, actor))
    if client is not None:
        return trainer.run(progress, client)
    with dask_client(workers=actor.actors if scheduler is None else None, scheduler=scheduler) as own:
        return trainer.run(progress, own)


# ---- several seeds at once ---------------------------------------------------------
def _train_seed(config: dict, out: str, resume: bool, total_steps: int | None) -> dict:
    """One seed's serial run (the task of --seeds): exactly `rad train --seed S --out out`."""
    try:
        return train(TrainConfig.from_dict(config), out, resume=resume, total_steps=total_steps)
    except RadError as e:
        raise RadError(str(e)) from None


def seed_folder(out: str | Path, seed: int) -> Path:
    return Path(out) / f'seed-{seed}'


def train_seeds(cfg: TrainConfig, out: str | Path, seeds: list[int], resume: bool = False,
                total_steps: int | None = None, scheduler: str | None = None, workers: int | None = None,
                progress=None, client=None) -> dict:
    """Serial runs of several seeds in parallel, one Dask task each, into out/seed-S.

    Each run is what `rad train --seed S --out out/seed-S` would do alone (same weights:
    each task is one serial Trainer in its own worker process, torch on one thread as
    --threads 1 sets). A LocalCluster of min(len(seeds), workers or len(seeds)) workers on
    127.0.0.1 unless `scheduler`/`client` is given. With resume each folder's checkpoint
    config wins. progress(seed, result) as runs finish. Returns {seed: result}."""
    from distributed import as_completed  # dask: only a scale-out run pays for its import
    from distributed.scheduler import KilledWorker  # dask: only a scale-out run pays for its import

    if not seeds:
        raise RadError('--seeds needs at least one seed, e.g. --seeds 1,2,3')
    if len(set(seeds)) != len(seeds):
        raise RadError(f'--seeds lists a seed twice: {seeds}')
    if not resume:
        cfg.validate()
        for s in seeds:
            if (seed_folder(out, s) / 'checkpoint.pt').exists():
                raise RadError(f'{str(seed_folder(out, s))!r} already holds a training run; use --resume')
    out = Path(out).resolve()
    base = asdict(cfg)
    if Path(cfg.dataset).exists():
        base['dataset'] = str(Path(cfg.dataset).resolve())

    def run(cl):
        futures = {cl.submit(_train_seed, {**base, 'seed': s}, str(seed_folder(out, s)), resume, total_steps,
                             key=f'rad-train-seed-{uuid.uuid4().hex[:8]}-{s}', pure=False): s for s in seeds}
        results = {}
        try:
            for f in as_completed(list(futures), loop=cl.loop):
                s = futures[f]
                try:
                    results[s] = f.result()
                except KilledWorker as e:
                    raise RadError(f'seed {s}: every worker that ran it died ({e})') from None
                except RadError as e:
                    raise RadError(f'seed {s}: {e}') from None
                if progress is not None:
                    progress(s, results[s])
        finally:
            pending = [f for f in futures if not f.done()]
            if pending:
                cl.cancel(pending)
        return {s: results[s] for s in seeds}

    if client is not None:
        return run(client)
    n = len(seeds) if workers is None else min(workers, len(seeds))
    with dask_client(workers=n if scheduler is None else workers, scheduler=scheduler) as own:
        return run(own)

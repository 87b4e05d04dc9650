"""DQN for the sequencing level, guided by the allocation (the paper's MILP-DQN).

Read top to bottom: `TrainConfig` (every knob, documented; those it shares with
`rad expert` are in `training.config`), `Trainer` (one training run: networks,
replay, the episode loop with epsilon-greedy exploration among the method's
action space plus terminate, the TD update against a target network,
evaluation, logs, checkpoints), `train()` (the entry point behind `rad train`).

Methods (the paper's Table I):
- milp-dqn: actions are the allocation's proposals (`AllocationActions`);
- dqn:      any unplaced unit at any free cell, any rotation (`all_actions`);
- dqn-rel:  only next to placed blocks, the first step on any target cell.
The environment is the no-robot MDP with physical stability (PyBullet), the
paper's reward (0.2 (dF - dE), -1 invalid, +1 complete) and gamma 0.999; with
`robot` it is the same MDP with the robot in the loop (`RobotAssemblyEnv`: GAMP
plans grasp and placement, the block is teleported to its pose and physics
settles and judges; an infeasible grasp (f_g) or placement (f_p), a disturbed
block or an unstable structure ends the episode with -1), in one PyBullet world
for the whole run, with the world put back to a function of the MDP state after
each step (`RobotEnvConfig.markov`) and the verdicts cached (`StepCache`, saved in
the checkpoint). `init` starts from a trained model (fine-tuning the no-robot
network with the robot: scripts/train_robot.sh).

Determinism: every random choice (scene sampling, exploration, replay
sampling) comes from one numpy Generator seeded with `seed`, the network from
torch's generator seeded with it; physics answers are reproducible. Two runs
with the same config give identical weights, and a run resumed from a
checkpoint continues exactly as if it had not stopped (checkpoints are taken
between episodes, with the replay buffer and all generator states).
"""

from __future__ import annotations

import csv
import math
import resource
import signal
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F

from rad_core.allocation import AllocationParams, solve
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.env.mdp import TERMINATE, AssemblyEnv, EnvConfig
from rad_core.env.robot_env import RobotAssemblyEnv, RobotEnvConfig, StepCache
from rad_core.learning import checkpoint as ckpt
from rad_core.learning.graph import GraphObs, Observer
from rad_core.learning.network import NetConfig, QNetwork, collate, graph_max, pick
from rad_core.learning.replay import ReplayBuffer, Transition
from rad_core.sequencing.decide.actions import action_space
from rad_core.sequencing.decide.episode import Decision, Episode, run_episode
from rad_core.sim.physics import PhysicsStability
from rad_core.training.config import LearnerConfig, knob
from rad_core.training.curves import plot_progress
from rad_core.training.dataset import Dataset

METHODS = {'milp-dqn': 'milp', 'dqn': 'all', 'dqn-rel': 'rel'}
VALIDATION_SEED_BASE = 500_000   # validation scenes: neither evaluation (0..) nor training (1e6..) seeds


@dataclass
class TrainConfig(LearnerConfig):
    """One training run: the shared knobs (`LearnerConfig`: seed, init, lr, batch_size,
    target_update, gamma, grad_clip, threads) and DQN's own. `rad train --<field-name-with-dashes>
    VALUE` sets any field."""

    method: str = knob('milp-dqn', "milp-dqn (allocation's actions), dqn (any unit, any free cell), dqn-rel "
                                   "(next to placed blocks)")
    dataset: str = knob('data/train-g3.jsonl.gz', 'training scenes with allocations (`rad dataset build`)')
    total_steps: int = knob(40_000, 'environment steps to train for')
    buffer_size: int = knob(30_000, 'replay capacity, transitions')
    learning_starts: int = knob(1_000, 'environment steps before the first gradient step')
    train_every: int = knob(4, 'environment steps per gradient step')
    eps_start: float = knob(1.0, 'initial exploration rate')
    eps_end: float = knob(0.05, 'final exploration rate')
    eps_fraction: float = knob(0.4, 'fraction of total_steps over which epsilon decays linearly')
    double: bool = knob(False, 'double DQN targets (online argmax, target value)')
    eval_every: int = knob(2_000, 'environment steps between greedy evaluations on validation scenes')
    eval_scenes: int = knob(50, 'validation scenes (generator seeds from 500000, never used elsewhere)')
    eval_grid: int = knob(3, 'g of the validation scenes')
    checkpoint_every_s: float = knob(120.0, 'seconds between training checkpoints (also on SIGINT and at the end)')
    device: str = knob('auto', "'auto' (cuda if present, else cpu), 'cpu', 'cuda', 'cuda:1', ...")
    robot: bool = knob(False, 'train (and validate) with the robot in the loop: GAMP, teleport execution, physics')
    robot_settle_s: float = knob(0.2, 'with the robot: simulated settling before a placement is judged (0.2 s '
                                      'gave the verdicts of 0.5 s on every placement measured)')
    dim: int = knob(64, 'network: node encoding width')
    heads: int = knob(4, 'network: attention heads')
    rounds: int = knob(3, 'network: message-passing rounds')
    ff: int = knob(512, 'network: feed-forward width in each round')
    readout: int = knob(128, 'network: hidden width of the Q heads')

    def validate(self) -> None:
        if self.method not in METHODS:
            raise RadError(f'method must be one of {", ".join(METHODS)}, got {self.method!r}')
        super().validate()
        self.require_positive('total_steps', 'buffer_size', 'train_every', 'eval_every', 'eval_scenes',
                              'dim', 'heads', 'rounds', 'ff', 'readout')
        if self.dim % self.heads:
            raise RadError(f'dim ({self.dim}) must be a multiple of heads ({self.heads})')
        if not (0 <= self.eps_end <= self.eps_start <= 1):
            raise RadError('need 0 <= eps_end <= eps_start <= 1')
        if not self.robot_settle_s > 0:
            raise RadError(f'robot_settle_s must be positive, got {self.robot_settle_s}')

    @property
    def net(self) -> NetConfig:
        return NetConfig(self.dim, self.heads, self.rounds, self.ff, self.readout)


def explore(env: AssemblyEnv, space, rng: np.random.Generator, epsilon: Callable[[], float],
            greedy: Callable[[GraphObs], int], record: Callable[[Transition], None], act=None) -> Episode:
    """One epsilon-greedy episode from the env's state: at each step, with probability epsilon() a
    uniform choice among the candidates space(env) and terminating, else greedy(observation) (a
    candidate's index, -1 for terminating); record(transition) after each step, in play order
    (the transition's next observation is the one the next decision sees). act: as `run_episode`'s.
    The serial trainer and the actors play their episodes with it."""
    observe = Observer(env)
    current = {}

    def decide(env: AssemblyEnv, rng: np.random.Generator) -> Decision:
        if 'obs' not in current:
            actions = space(env)
            current.update(obs=observe(env, actions), actions=actions)
        actions = current['actions']
        if rng.random() < epsilon():
            k = int(rng.integers(len(actions) + 1)) - 1   # uniform over candidates and terminate
        else:
            k = greedy(current['obs'])
        current['k'] = k
        return Decision(actions[k] if k >= 0 else TERMINATE)

    def on_step(decision: Decision, result) -> None:
        nxt = {}
        if not result.done:
            actions = space(env)
            nxt = {'obs': observe(env, actions), 'actions': actions}
        transition = Transition(current['obs'], current['k'], float(result.reward), bool(result.done),
                                nxt.get('obs'))
        current.clear()
        current.update(nxt)
        record(transition)

    return run_episode(env, decide, rng, act, on_step=on_step)


def pick_device(name: str) -> torch.device:
    if name == 'auto':
        return torch.device('cuda' if torch.cuda.is_available() else 'cpu')
    try:
        dev = torch.device(name)
    except RuntimeError as e:
        raise RadError(f'--device {name!r}: {e}') from None
    if dev.type == 'cuda' and not torch.cuda.is_available():
        raise RadError(f'--device {name!r}: no CUDA device here')
    return dev


class Trainer:
    def __init__(self, cfg: TrainConfig, out: str | Path):
        cfg.validate()
        self.cfg, self.out = cfg, Path(out)
        self.device = pick_device(cfg.device)
        torch.set_num_threads(cfg.threads)
        torch.manual_seed(cfg.seed)
        self.rng = np.random.default_rng(cfg.seed)
        self.q = QNetwork(cfg.net).to(self.device)
        self.target = QNetwork(cfg.net).to(self.device)
        self.actions = METHODS[cfg.method]
        if cfg.init:
            self._load_init(cfg.init)
        self.target.load_state_dict(self.q.state_dict())
        self.opt = torch.optim.Adam(self.q.parameters(), lr=cfg.lr)
        self.replay = ReplayBuffer(cfg.buffer_size)
        self.pos = {'env_steps': 0, 'grad_steps': 0, 'episodes': 0, 'wall_s': 0.0, 'next_eval': cfg.eval_every,
                    # Fixed when the run starts: extending a run with --total-steps must not
                    # move the exploration schedule.
                    'eps_horizon': max(1.0, cfg.eps_fraction * cfg.total_steps)}
        self.recent: list[tuple[float, float]] = []   # (return, coverage) of recent training episodes
        self.losses: list[float] = []
        self.best_eval = -math.inf
        self.dataset = Dataset.load(cfg.dataset)
        self.stability = self.robot = self.step_cache = None
        if cfg.robot:
            self.step_cache = StepCache()
        else:
            self.stability = PhysicsStability()
        self._validation = None
        self._writer = None
        self._stop = False

    def _load_init(self, name: str) -> None:
        path = ckpt.resolve(name)
        doc = ckpt.read(path, ckpt.MODEL_FORMAT)
        if doc.get('actions') != self.actions:
            raise RadError(f'--init {name}: a model of the {doc.get("actions")!r} action space; '
                           f'{self.cfg.method} chooses among {self.actions!r}')
        if doc.get('net') != self.cfg.net.to_dict():
            raise RadError(f'--init {name}: network sizes {doc.get("net")} differ from this run\'s '
                           f'{self.cfg.net.to_dict()} (pass the same --dim/--heads/--rounds/--ff/--readout)')
        ckpt.load_weights(self.q, doc['weights'], path)

    # ---- exploration and acting ------------------------------------------------------
    def epsilon(self) -> float:
        c = self.cfg
        horizon = self.pos.get('eps_horizon', max(1.0, c.eps_fraction * c.total_steps))
        frac = min(1.0, self.pos['env_steps'] / horizon)
        return c.eps_start + frac * (c.eps_end - c.eps_start)

    @torch.no_grad()
    def greedy(self, obs: GraphObs) -> int:
        """Index of the best candidate, -1 when terminating is best."""
        batch = collate([obs], self.device)
        qa, qs = self.q(batch)
        _, arg = graph_max(qa, qs, batch)
        return int(arg[0])

    def make_env(self, scene) -> AssemblyEnv:
        """The env of an episode on `scene`, reset; with the robot, the bookkeeping
        env of the run's one RobotAssemblyEnv (step it with `act`)."""
        if not self.cfg.robot:
            return AssemblyEnv(scene, EnvConfig(stability='physics', gamma=self.cfg.gamma), stability=self.stability)
        if self.robot is None:
            config = RobotEnvConfig(env=EnvConfig(stability='none', gamma=self.cfg.gamma), execution='teleport',
                                    settle_s=self.cfg.robot_settle_s, markov=True, cache=True)
            self.robot = RobotAssemblyEnv(scene, config, cache=self.step_cache)
        else:
            self.robot.load(scene)
        self.robot.reset()
        return self.robot.env

    def act(self, decision: Decision):
        """How an episode's step is carried out: None = the env's own step (no robot)."""
        return self.robot.step(decision.action)

    def close(self) -> None:
        if self.robot is not None:
            self.robot.close()
            self.robot = None

    def episode(self) -> None:
        """One training episode on a random dataset scene, learning as it goes."""
        entry = self.dataset.entries[int(self.rng.integers(len(self.dataset)))]
        env = self.make_env(entry.scene())

        def learn_from(transition: Transition) -> None:
            self.replay.add(transition)
            self.pos['env_steps'] += 1
            steps = self.pos['env_steps']
            if steps >= self.cfg.learning_starts and steps % self.cfg.train_every == 0:
                self.learn()
            if steps % self.cfg.target_update == 0:
                self.target.load_state_dict(self.q.state_dict())

        ep = explore(env, action_space(self.actions, env, entry.placements), self.rng, self.epsilon, self.greedy,
                     learn_from, self.act if self.cfg.robot else None)
        self.pos['episodes'] += 1
        self.recent = (self.recent + [(ep.ret, ep.coverage)])[-100:]

    # ---- learning --------------------------------------------------------------------
    def learn(self) -> None:
        c = self.cfg
        batch = self.replay.sample(c.batch_size, self.rng)
        b = collate([t.obs for t in batch], self.device)
        k = torch.tensor([t.action for t in batch], device=self.device)
        r = torch.tensor([t.reward for t in batch], dtype=torch.float32, device=self.device)
        chosen = pick(*self.q(b), b, k)
        with torch.no_grad():
            y = r.clone()
            live = [i for i, t in enumerate(batch) if not t.done]
            if live:
                nb = collate([batch[i].next_obs for i in live], self.device)
                tqa, tqs = self.target(nb)
                if c.double:
                    _, arg = graph_max(*self.q(nb), nb)
                    value = pick(tqa, tqs, nb, arg)
                else:
                    value, _ = graph_max(tqa, tqs, nb)
                y[live] += c.gamma * value
        loss = F.smooth_l1_loss(chosen, y)
        self.opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.q.parameters(), c.grad_clip)
        self.opt.step()
        self.pos['grad_steps'] += 1
        self.losses.append(float(loss.detach()))

    # ---- evaluation ------------------------------------------------------------------
    def validation(self):
        if self._validation is None:
            config = GeneratorConfig(grid=self.cfg.eval_grid)
            scenes = [generate_scene(config, VALIDATION_SEED_BASE + i) for i in range(self.cfg.eval_scenes)]
            # Validate with the allocation the training data was made with.
            params = AllocationParams(support=self.dataset.header.get('allocation', {}).get('support', 'none'))
            self._validation = [(s, solve(s, params).placements) for s in scenes]
        return self._validation

    def evaluate(self) -> dict:
        """Greedy episodes on the validation scenes: mean return, coverage and the
        fraction of episodes that ended on an invalid action (with the robot: f)."""
        rets, covs, fails = [], [], []
        for scene, placements in self.validation():
            env = self.make_env(scene)
            space = action_space(self.actions, env, placements)
            observe = Observer(env)

            def decide(env, rng):
                actions = space(env)
                k = self.greedy(observe(env, actions))
                return Decision(actions[k] if k >= 0 else TERMINATE)

            ep = run_episode(env, decide, np.random.default_rng(0), self.act if self.cfg.robot else None)
            rets.append(ep.ret)
            covs.append(ep.coverage)
            fails.append(bool(ep.outcome is not None and ep.outcome.is_invalid))
        out = {'eval_return': float(np.mean(rets)), 'eval_coverage': float(np.mean(covs))}
        if self.cfg.robot:
            out['eval_failures'] = float(np.mean(fails))
        return out

    # ---- logs, checkpoints -----------------------------------------------------------
    def log(self, row: dict) -> None:
        path = self.out / 'progress.csv'
        new = not path.exists()
        with open(path, 'a', newline='') as f:
            w = csv.DictWriter(f, fieldnames=list(row))
            if new:
                w.writeheader()
            w.writerow(row)
        if self._writer is None:
            from tensorboardX import SummaryWriter  # tensorboardX: only a run that logs to it pays for its import
            self._writer = SummaryWriter(str(self.out / 'tb'))
        for key, value in row.items():
            if key != 'env_steps' and isinstance(value, (int, float)) and math.isfinite(value):
                self._writer.add_scalar(key, value, row['env_steps'])
        self._writer.flush()

    def model_doc(self) -> dict:
        # What the network was trained for travels with it: its action space and the allocation
        # (support rule) of its training data, which an agent naming it then runs with.
        return {'format': ckpt.MODEL_FORMAT, 'method': self.cfg.method, 'actions': self.actions,
                'support': self.dataset.header.get('allocation', {}).get('support', 'none'),
                'net': self.cfg.net.to_dict(), 'weights': self.q.state_dict(),
                'train': {'config': asdict(self.cfg), 'position': dict(self.pos),
                          'best_eval_return': self.best_eval}}

    def save(self) -> None:
        model = self.model_doc()
        ckpt.atomic_save({**model, 'format': ckpt.TRAIN_FORMAT, 'target': self.target.state_dict(),
                          'optimizer': self.opt.state_dict(), 'replay': self.replay.state_dict(),
                          'rng': self.rng.bit_generator.state, 'torch_rng': torch.get_rng_state(),
                          'position': dict(self.pos), 'recent': self.recent, 'best_eval': self.best_eval,
                          'step_cache': self.step_cache.state_dict() if self.step_cache is not None else None},
                         self.out / 'checkpoint.pt')
        ckpt.atomic_save(model, self.out / 'model.pt')

    def restore(self, path: Path) -> None:
        doc = ckpt.read(path, ckpt.TRAIN_FORMAT, weights_only=False)
        ckpt.load_weights(self.q, doc['weights'], path)
        ckpt.load_weights(self.target, doc['target'], path, 'target weights')
        self.opt.load_state_dict(doc['optimizer'])
        self.replay.load_state_dict(doc['replay'])
        self.rng.bit_generator.state = doc['rng']
        torch.set_rng_state(doc['torch_rng'])
        self.pos = dict(doc['position'])
        self.recent = list(doc['recent'])
        self.best_eval = doc['best_eval']
        if self.step_cache is not None and doc.get('step_cache') is not None:
            self.step_cache.load_state_dict(doc['step_cache'])
        # Rows logged after this checkpoint (the run was killed later) would be logged again.
        progress = self.out / 'progress.csv'
        if progress.exists():
            lines = progress.read_text().splitlines(keepends=True)
            keep = lines[:1] + [ln for ln in lines[1:] if int(ln.split(',')[0]) <= self.pos['env_steps']]
            progress.write_text(''.join(keep))

    # ---- the run -----------------------------------------------------------------------
    def run(self, progress=None) -> dict:
        c = self.cfg
        self.out.mkdir(parents=True, exist_ok=True)
        # Python handles signals in the main thread only: a run in a worker thread (a Dask
        # task of `rad train --seeds`) is stopped by its process instead.
        main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, self._on_sigint) if main else None
        t_start, last_ckpt = time.perf_counter() - self.pos['wall_s'], time.perf_counter()
        mark = (time.perf_counter(), self.pos['env_steps'], self.pos['grad_steps'])
        interrupted = False
        try:
            if c.init and self.pos['env_steps'] == 0 and not (self.out / 'progress.csv').exists():
                self.log(self._report(mark))   # where the starting model stands, at step 0
            while self.pos['env_steps'] < c.total_steps:
                self.episode()
                mark = self._after_steps(t_start, mark, progress)
                if self._stop:
                    interrupted = True
                    break
                last_ckpt = self._checkpoint_due(last_ckpt)
            self.save()
        finally:
            if main:
                signal.signal(signal.SIGINT, previous)
            self.close()
            if self._writer is not None:
                self._writer.close()
        if not interrupted:
            title = f'{c.method} seed {c.seed}' + (' (robot)' if c.robot else '')
            plot_progress(self.out / 'progress.csv', self.out / 'curves.png', title=title)
        return {'interrupted': interrupted, **self.pos}

    def _on_sigint(self, signum, frame) -> None:
        # Finish the episode in progress, checkpoint, then stop (a second Ctrl-C kills).
        self._stop = True
        signal.signal(signal.SIGINT, signal.default_int_handler)

    def _after_steps(self, t_start: float, mark: tuple, progress) -> tuple:
        """After new environment steps: wall time, the progress callback, and at each
        eval_every (and the end) a validation row logged. Returns the new eval mark."""
        c = self.cfg
        self.pos['wall_s'] = time.perf_counter() - t_start
        if progress is not None:
            progress(self.pos['env_steps'])
        if self.pos['env_steps'] >= self.pos['next_eval'] or self.pos['env_steps'] >= c.total_steps:
            self.pos['next_eval'] += c.eval_every
            row = self._report(mark)
            mark = (time.perf_counter(), self.pos['env_steps'], self.pos['grad_steps'])
            self.log(row)
        return mark

    def _checkpoint_due(self, last_ckpt: float) -> float:
        """Save when checkpoint_every_s has passed since last_ckpt; the time of the last save."""
        if time.perf_counter() - last_ckpt > self.cfg.checkpoint_every_s:
            self.save()
            return time.perf_counter()
        return last_ckpt

    def _report(self, mark) -> dict:
        t0, s0, g0 = mark
        dt = max(time.perf_counter() - t0, 1e-9)
        ev = self.evaluate()
        self.best_eval = max(self.best_eval, ev['eval_return'])
        recent = np.array(self.recent) if self.recent else np.zeros((1, 2))
        loss = float(np.mean(self.losses)) if self.losses else float('nan')
        self.losses = []
        return {'env_steps': self.pos['env_steps'], 'grad_steps': self.pos['grad_steps'],
                'episodes': self.pos['episodes'], 'epsilon': round(self.epsilon(), 4), 'loss': loss,
                'train_return': float(recent[:, 0].mean()), 'train_coverage': float(recent[:, 1].mean()),
                **ev, 'env_steps_per_s': (self.pos['env_steps'] - s0) / dt,
                'grad_steps_per_s': (self.pos['grad_steps'] - g0) / dt, 'wall_s': round(self.pos['wall_s'], 1),
                'peak_rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                **({'cache_hit_rate': self.step_cache.hits / max(1, self.step_cache.hits + self.step_cache.misses)}
                   if self.step_cache is not None else {})}


def open_run(cfg: TrainConfig, out: str | Path, resume: bool = False, total_steps: int | None = None,
             make: Callable[[TrainConfig, Path], Trainer] = Trainer) -> Trainer:
    """The trainer of the run in `out`, made by make(config, out): with resume, the run its
    checkpoint holds, restored (the checkpoint's config wins; total_steps may extend it); else a
    new run with `cfg`, refusing a folder that holds one already."""
    out = Path(out)
    path = out / 'checkpoint.pt'
    if resume:
        doc = ckpt.read(path, ckpt.TRAIN_FORMAT, weights_only=False)
        cfg = TrainConfig.from_dict(doc['train']['config'])
        if total_steps is not None:
            cfg.total_steps = total_steps
        trainer = make(cfg, out)
        trainer.restore(path)
        return trainer
    if path.exists():
        raise RadError(f'{str(out)!r} already holds a training run; use --resume to continue it, '
                       f'or another --out')
    return make(cfg, out)


def train(cfg: TrainConfig, out: str | Path, resume: bool = False, total_steps: int | None = None,
          progress=None) -> dict:
    """Train (or with resume, continue the run in `out` from its checkpoint, whose
    config wins; total_steps may extend it). Writes out/progress.csv, out/tb/,
    out/checkpoint.pt, out/model.pt, out/curves.png."""
    return open_run(cfg, out, resume, total_steps).run(progress)

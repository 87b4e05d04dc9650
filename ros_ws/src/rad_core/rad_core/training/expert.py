"""Expert iteration: the network learns what the planner around it finds (issue 17).

The expert is an agent built around the network: by default `default` (the network ranks, GAMP
verifies every step, re-allocation and order repair improve the plan), with the robot in the loop
(the in-process parts `/plan_assembly` has). On a training scene the plan it keeps is the expert's
line. Every state along the line, with the action the line took there (and 'terminate' where the
line ended short of the target), is a demonstration; the rewards of the line make its transitions.

The network is trained on the demonstrations as DQfD does (Hester et al., "Deep Q-learning from
Demonstrations", 2018): the one-step TD loss against a target network, beside a large-margin loss
that asks the expert's action to be valued at least `margin` above every other candidate and
terminating. Rounds alternate: plan the round's scenes with the current network inside the
expert, then train on every demonstration collected so far (data aggregation, as DAgger and
expert iteration do), from the weights of the round before.

Where the expert's line differs from the network's own choice, the network learns something:
an action GAMP refused (the verified plan took the next), an order repair found, a pose a
re-allocation proposed. Where it does not, the loss keeps what the network knew.

Run folder (`rad expert --out runs/NAME`):
- `demos/rR/NAME.pkl`: one scene's demonstrations and the expert's plan summary, written
  atomically when the scene is planned (a killed round goes on with the scenes not yet planned);
- `rR.pt`: the network after round R (`rad-qnet/1`, loads with `--checkpoint`); `model.pt`: the
  last round's; `progress.jsonl`: one row per round (scenes, demonstrations, the expert's coverage,
  agreement with the expert on held-out scenes before and after training, losses, time).
Resuming (`--resume`) skips finished rounds and planned scenes; a round's training, a few minutes,
starts again from the round before's weights.
"""

from __future__ import annotations

import json
import os
import pickle
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from rad_core.domain import hard_shapes, shapes
from rad_core.domain.errors import RadError
from rad_core.domain.generator import GeneratorConfig, generate_scene
from rad_core.domain.scene import Scene
from rad_core.env.mdp import TERMINATE, AssemblyEnv, EnvConfig
from rad_core.experiment.distributed import dask_client, dask_setup
from rad_core.gamp.action import SceneAction
from rad_core.learning import checkpoint as ckpt
from rad_core.learning.network import NetConfig, QNetwork, collate, graph_max, pick
from rad_core.learning.policy import QPolicy
from rad_core.learning.replay import Transition
from rad_core.sequencing.agent.agent_plan import AgentPlanner
from rad_core.sequencing.decide.actions import mdp_actions
from rad_core.sequencing.decide.agents import parse
from rad_core.training.config import LearnerConfig, knob

TRAIN_SEED_BASE = 3_000_000
"""Generator seeds of the expert's generated scenes: neither evaluation (0..), validation (500000..)
nor the DQN datasets' (1000000..)."""


@dataclass
class ExpertConfig(LearnerConfig):
    """One expert-iteration run: the shared knobs (`LearnerConfig`: seed, init, lr, batch_size,
    target_update, gamma, grad_clip, threads) and the expert's own. `rad expert
    --<field-name-with-dashes> VALUE` sets any field."""

    init: str = LearnerConfig.with_default('init', 'milp-dqn-mixed')
    lr: float = LearnerConfig.with_default('lr', 3e-5)
    target_update: int = LearnerConfig.with_default('target_update', 500)
    agent: str = knob('default', 'the expert: an agent around the network (its scorer is replaced by the '
                                 'current network); it needs the robot-verified plan (verify)')
    grids: str = knob('4,5,6', 'comma-separated g of the generated training scenes')
    scenes: int = knob(20, 'generated scenes per grid size and round')
    shapes: bool = knob(True, "also the training splits of the hand-made and the hard shapes, one layout per round")
    rounds: int = knob(2, 'collect-and-train rounds')
    steps: int = knob(400, 'gradient steps per round')
    margin: float = knob(0.02, "the large-margin loss's margin (Q units; the shipped network's best two candidates "
                               "lie 0.014 apart at the median)")
    expert_weight: float = knob(1.0, 'weight of the large-margin loss beside the TD loss')
    td_weight: float = knob(1.0, 'weight of the one-step TD loss')
    anchor_weight: float = knob(10.0, "weight of the squared difference to the starting network's values on every "
                                      "candidate (0: none); without it a few hundred steps reorder the network's "
                                      "near-tied candidates everywhere")
    weight_decay: float = knob(1e-5, 'L2 regularisation (Adam weight decay), as DQfD')
    holdout: float = knob(0.15, 'fraction of each round\'s scenes whose demonstrations only measure agreement')
    time_limit_s: float = knob(120.0, "the expert's planning time limit per scene")
    workers: int = knob(2, 'Dask worker processes planning scenes (1: in this process)')

    def validate(self) -> None:
        super().validate()
        self.require_positive('scenes', 'rounds', 'steps', 'workers')
        if not (self.margin >= 0 and min(self.expert_weight, self.td_weight, self.anchor_weight) >= 0):
            raise RadError('need margin >= 0, and expert_weight, td_weight and anchor_weight >= 0')
        if not 0 <= self.holdout < 1:
            raise RadError(f'holdout must be in [0, 1), got {self.holdout}')
        self.grid_sizes()
        spec = parse(self.agent)
        if not spec.learned or not spec.verify:
            raise RadError(f'the expert must be a learned, verified agent (a network with +verify), '
                           f'got {self.agent!r}')

    def grid_sizes(self) -> list[int]:
        try:
            grids = [int(g) for g in str(self.grids).split(',') if g.strip()]
        except ValueError:
            raise RadError(f'grids must be comma-separated whole numbers, got {self.grids!r}') from None
        if any(g < 2 for g in grids):
            raise RadError(f'grids must be at least 2, got {self.grids!r}')
        return grids


# ---- demonstrations -----------------------------------------------------------------
class RecordingPolicy:
    """A `QPolicy` that keeps, for every world it scores (the scene's text), the observation and
    the candidate actions: what the network saw where the expert chose."""

    def __init__(self, policy):
        self.policy = policy
        self.records: dict[str, list] = {}

    def __getattr__(self, name):
        return getattr(self.policy, name)

    @torch.no_grad()
    def scores(self, env: AssemblyEnv, actions, rng=None) -> np.ndarray:
        obs = self.policy.observer(env)(env, actions)
        qa, qs = self.policy.net(collate([obs], self.policy.device))
        self.records.setdefault(env.scene.dumps(), []).append((obs, list(actions)))
        return np.concatenate([qa.cpu().numpy(), qs.cpu().numpy()]).astype(float)


def demonstrations(scene, plan, records: dict) -> list[Transition]:
    """The expert's line as transitions: for each step of `plan` (an `AssemblyPlan` of `scene`), the
    observation the network scored in that world, the index of the action the plan took, the
    MDP's reward and the next world's observation; then 'terminate' where the plan stopped short
    of the target. A world nobody scored (none, when the recorder ranked every step) ends the line
    there (its last transition then has neither a next observation nor done: no TD target)."""
    if plan.allocation is None:
        return []
    env = AssemblyEnv(scene, EnvConfig(stability='none'))   # the rewards (every step was judged by the plan)
    world, out = scene, []

    def observed(action=None):
        """The last record of this world whose candidates hold `action` (any, for None)."""
        for obs, actions in reversed(records.get(world.dumps(), [])):
            if action is None:
                return obs, actions
            if action in actions:
                return obs, actions
        return None

    def link(obs) -> None:
        if out and not out[-1].done:
            out[-1] = out[-1]._replace(next_obs=obs)

    for step in plan.steps:
        want = SceneAction(step.block, step.unit, step.target, tuple(step.cell), step.rotation)
        action = next(iter(mdp_actions(env, [want])), None)
        seen = observed(action) if action is not None else None
        if seen is None:
            return out
        obs, actions = seen
        link(obs)
        result = env.step(action)
        out.append(Transition(obs, actions.index(action), float(result.reward), bool(result.done), None))
        world = step.scene_after(world)
    if not env.state.done:
        seen = observed()
        if seen is not None:
            link(seen[0])
            result = env.step(TERMINATE)
            out.append(Transition(seen[0], -1, float(result.reward), True, None))
    return out


# ---- the worker side: planning one scene ----------------------------------------------
_PLANNERS: dict = {}


def _planner(agent: str, model: str, time_limit_s: float):
    """This process's expert (an `AgentPlanner` with a recording network), one per model file."""

    key = (agent, model, os.path.getmtime(model), time_limit_s)
    if key not in _PLANNERS:
        dask_setup()
        for old in _PLANNERS.values():
            old.close()
        _PLANNERS.clear()
        spec = replace(parse(agent), scorer=model)
        policy = RecordingPolicy(QPolicy.load(model))
        _PLANNERS[key] = AgentPlanner(spec, time_limit_s=time_limit_s, policy=policy)
    return _PLANNERS[key]


def plan_scene(name: str, scene_doc: dict, agent: str, model: str, time_limit_s: float, seed: int = 0) -> dict:
    """Plan one scene with the expert; its demonstrations and what the plan reached."""
    scene = Scene.from_dict(scene_doc)
    planner = _planner(agent, model, time_limit_s)
    planner.sequencer.policy.records = {}
    t0 = time.perf_counter()
    plan = planner(scene, seed=seed)
    demos = demonstrations(scene, plan, planner.sequencer.policy.records)
    planner.sequencer.policy.records = {}
    return {'name': name, 'coverage': float(plan.predicted_coverage), 'steps': len(plan.steps),
            'kept': plan.anytime[-1]['plan'] if plan.anytime else '', 'seconds': time.perf_counter() - t0,
            'reallocations': len(plan.reallocations), 'demos': demos}


# ---- the learner -----------------------------------------------------------------------
def dqfd_loss(q: QNetwork, target: QNetwork, batch: list[Transition], gamma: float, margin: float,
              expert_weight: float, device, td_weight: float = 1.0, anchor: QNetwork | None = None,
              anchor_weight: float = 0.0) -> tuple[torch.Tensor, dict]:
    """td_weight times TD (smooth L1, one step, target network) plus expert_weight times the
    large-margin loss max_a [Q(s, a) + margin (a != a_E)] - Q(s, a_E), over the candidates and
    terminating, plus anchor_weight times the mean squared difference to `anchor`'s values of every
    candidate and terminating. Returns the loss and each term's value."""
    b = collate([t.obs for t in batch], device)
    k = torch.tensor([t.action for t in batch], device=device)
    qa, qs = q(b)
    chosen = pick(qa, qs, b, k)
    if qa.numel():
        local = torch.arange(qa.numel(), device=device) - b.offsets[b.act_graph]
        qa_m = qa + margin * (local != k[b.act_graph]).to(qa.dtype)
    else:
        qa_m = qa
    qs_m = qs + margin * (k >= 0).to(qs.dtype)
    best, _ = graph_max(qa_m, qs_m, b)
    expert = (best - chosen).mean()
    r = torch.tensor([t.reward for t in batch], dtype=torch.float32, device=device)
    y = r.clone()
    usable = torch.tensor([t.done or t.next_obs is not None for t in batch], device=device)
    live = [i for i, t in enumerate(batch) if not t.done and t.next_obs is not None]
    if live:
        with torch.no_grad():
            nb = collate([batch[i].next_obs for i in live], device)
            value, _ = graph_max(*target(nb), nb)
        y[live] += gamma * value
    td = F.smooth_l1_loss(chosen[usable], y[usable]) if usable.any() else chosen.sum() * 0.0
    info = {'td': float(td.detach()), 'margin': float(expert.detach())}
    loss = td_weight * td + expert_weight * expert
    if anchor is not None and anchor_weight > 0:
        with torch.no_grad():
            aa, as_ = anchor(b)
        kept = (F.mse_loss(qa, aa) if qa.numel() else qa.sum() * 0.0) + F.mse_loss(qs, as_)
        info['anchor'] = float(kept.detach())
        loss = loss + anchor_weight * kept
    return loss, info


@torch.no_grad()
def agreement(q: QNetwork, demos: list[Transition], device, batch: int = 64) -> float:
    """How often the network's own choice (its best candidate or terminating) is the expert's."""
    if not demos:
        return float('nan')
    q.eval()
    hits = 0
    for i in range(0, len(demos), batch):
        part = demos[i:i + batch]
        b = collate([t.obs for t in part], device)
        _, arg = graph_max(*q(b), b)
        hits += int((arg.cpu() == torch.tensor([t.action for t in part])).sum())
    q.train()
    return hits / len(demos)


class ExpertIteration:
    def __init__(self, cfg: ExpertConfig, out: str | Path):
        cfg.validate()
        self.cfg, self.out = cfg, Path(out)
        torch.set_num_threads(cfg.threads)
        self.device = torch.device('cpu')
        path = ckpt.resolve(cfg.init)
        self.init_doc = ckpt.read(path, ckpt.MODEL_FORMAT)
        if self.init_doc.get('actions') != 'milp':
            raise RadError(f'--init {cfg.init}: the expert chooses among the allocation\'s actions; '
                           f'this network was trained on {self.init_doc.get("actions")!r}')
        self.q = QNetwork(NetConfig(**self.init_doc['net']))
        ckpt.load_weights(self.q, self.init_doc['weights'], path)
        self._scenes: dict[int, list[tuple[str, dict, bool]]] = {}

    # ---- scenes -------------------------------------------------------------------------
    def scenes(self, r: int) -> list[tuple[str, dict, bool]]:
        """Round r's (name, scene document, held out): generated scenes of every grid size at seeds
        no other use has, and one layout of each training shape (made once per round)."""
        if r not in self._scenes:
            self._scenes[r] = self._make_scenes(r)
        return self._scenes[r]

    def _make_scenes(self, r: int) -> list[tuple[str, dict, bool]]:
        c = self.cfg
        out = []
        for g in c.grid_sizes():
            for i in range(c.scenes):
                seed = TRAIN_SEED_BASE + 100_000 * g + r * c.scenes + i
                out.append((f'g{g}-s{seed}', generate_scene(GeneratorConfig(grid=g), seed).to_dict()))
        if c.shapes:
            for name in shapes.SPLITS['train']:
                out.append((f'shape-{name}-r{r}', _first_layout(shapes.shape_scene, name, r)))
            for name in hard_shapes.HARD_SPLITS['train']:
                out.append((f'hard-{name}-r{r}', _first_layout(hard_shapes.hard_scene, name, r)))
        rng = np.random.default_rng([c.seed, r])
        held = set(rng.choice(len(out), size=int(round(c.holdout * len(out))), replace=False).tolist())
        return [(name, doc, i in held) for i, (name, doc) in enumerate(out)]

    # ---- files ---------------------------------------------------------------------------
    def model_path(self, r: int) -> Path:
        return self.out / f'r{r}.pt'

    def demo_path(self, r: int, name: str) -> Path:
        return self.out / 'demos' / f'r{r}' / f'{name}.pkl'

    def save_model(self, r: int, row: dict) -> None:
        doc = {**self.init_doc, 'weights': self.q.state_dict(),
               'train': {'expert': asdict(self.cfg), 'round': r, 'row': row}}
        ckpt.atomic_save(doc, self.model_path(r))
        ckpt.atomic_save(doc, self.out / 'model.pt')

    def progress(self) -> list[dict]:
        path = self.out / 'progress.jsonl'
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.exists() else []

    # ---- a round ---------------------------------------------------------------------------
    def collect(self, r: int, model: str, log) -> list[dict]:
        """Plan round r's scenes not yet planned (with `model` in the expert); every scene's summary."""
        c = self.cfg
        todo = [(n, d, h) for n, d, h in self.scenes(r) if not self.demo_path(r, n).exists()]
        log(f'round {r}: planning {len(todo)} scenes with {model}')

        def keep(result: dict, held: bool) -> None:
            result['held_out'] = held
            ckpt.atomic_save(result, self.demo_path(r, result['name']), save=_pickle)
            log(f'  {result["name"]}: coverage {result["coverage"]:.3f}, {len(result["demos"])} demos, '
                f'{result["seconds"]:.1f} s ({result["kept"]})')

        if c.workers == 1:
            for n, d, h in todo:
                keep(plan_scene(n, d, c.agent, model, c.time_limit_s), h)
        elif todo:
            from distributed import as_completed  # dask: only a scale-out run pays for its import

            # Spawned workers (Dask's default): this process has run torch by the second round,
            # and a process forked after that may hang in OpenMP.
            with dask_client(c.workers) as client:
                futures = {client.submit(plan_scene, n, d, c.agent, model, c.time_limit_s, pure=False): h
                           for n, d, h in todo}
                for fut in as_completed(list(futures), loop=client.loop):
                    keep(fut.result(), futures[fut])
        return [_read_pickle(self.demo_path(r, n)) for n, _, _ in self.scenes(r)]

    def train(self, demos: list[Transition], held: list[Transition], r: int, log, after_step=None) -> dict:
        """Round r's gradient steps on the training demonstrations; after_step(step), when given, is
        called after each (`benchmarks/bench_expert.py` measures agreement there)."""
        c = self.cfg
        torch.manual_seed(c.seed * 1000 + r)
        rng = np.random.default_rng([c.seed, r, 1])
        target = QNetwork(self.q.cfg)
        target.load_state_dict(self.q.state_dict())
        anchor = QNetwork(self.q.cfg).eval()      # the round's starting values
        anchor.load_state_dict(self.q.state_dict())
        opt = torch.optim.Adam(self.q.parameters(), lr=c.lr, weight_decay=c.weight_decay)
        def agree() -> dict:
            return {'agree_train': agreement(self.q, demos, self.device),
                    'agree_held': agreement(self.q, held, self.device)}
        before = agree()
        log(f'round {r}: {len(demos)} demonstrations ({len(held)} held out); agreement before '
            f'{before["agree_train"]:.3f} / held out {before["agree_held"]:.3f}')
        self.q.train()
        parts = {'td': [], 'margin': [], 'anchor': []}
        t0 = time.perf_counter()
        for step in range(1, c.steps + 1):
            batch = [demos[i] for i in rng.integers(0, len(demos), size=c.batch_size)]
            loss, info = dqfd_loss(self.q, target, batch, c.gamma, c.margin, c.expert_weight, self.device,
                                   td_weight=c.td_weight, anchor=anchor, anchor_weight=c.anchor_weight)
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.q.parameters(), c.grad_clip)
            opt.step()
            for k, v in info.items():
                parts[k].append(v)
            if step % c.target_update == 0:
                target.load_state_dict(self.q.state_dict())
            if step % 500 == 0 or step == c.steps:
                log(f'  step {step}: ' + ', '.join(f'{k} {np.mean(v[-500:]):.4f}' for k, v in parts.items() if v))
            if after_step is not None:
                after_step(step)
        self.q.eval()
        return {**{f'{k}_before': v for k, v in before.items()},
                **agree(),
                **{k: float(np.mean(v[-500:])) for k, v in parts.items() if v},
                'train_s': time.perf_counter() - t0}

    def run(self, resume: bool = False, log=print) -> list[dict]:
        c = self.cfg
        self.out.mkdir(parents=True, exist_ok=True)
        done = self.progress()
        if done and not resume:
            raise RadError(f'{str(self.out)!r} already holds an expert-iteration run; use --resume to continue it')
        config_path = self.out / 'config.json'
        if resume and config_path.exists():
            saved = json.loads(config_path.read_text())
            mine = asdict(c)
            changed = sorted(k for k in set(saved) | set(mine) if k != 'rounds' and saved.get(k) != mine.get(k))
            if changed:
                raise RadError(f'--resume continues {str(self.out)!r} with its own configuration ({config_path}); '
                               f'only --rounds may change, not --{changed[0].replace("_", "-")}')
        config_path.write_text(json.dumps(asdict(c), indent=1))
        if done:
            path = self.model_path(done[-1]['round'])
            ckpt.load_weights(self.q, ckpt.read(path, ckpt.MODEL_FORMAT)['weights'], path)
        t_run = time.perf_counter()
        for r in range(len(done), c.rounds):
            t0 = time.perf_counter()
            model = str(self.model_path(r - 1).resolve()) if r else str(ckpt.resolve(c.init).resolve())
            results = self.collect(r, model, log)
            train_demos, held_demos = [], []
            for rr in range(r + 1):       # every round's demonstrations so far
                earlier = results if rr == r else [_read_pickle(self.demo_path(rr, n)) for n, _, _ in self.scenes(rr)]
                for res in earlier:
                    (held_demos if res['held_out'] else train_demos).extend(res['demos'])
            collect_s = time.perf_counter() - t0
            row = {'round': r, 'expert_model': model, 'scenes': len(results),
                   'expert_coverage': float(np.mean([x['coverage'] for x in results])),
                   'expert_plan_s': float(np.sum([x['seconds'] for x in results])),
                   'repair_kept': sum(x['kept'] == 'repair' for x in results),
                   'demos': len(train_demos), 'held_demos': len(held_demos), 'collect_s': collect_s}
            if not train_demos:
                raise RadError(f'round {r}: the expert left no demonstrations')
            row.update(self.train(train_demos, held_demos, r, log))
            row['round_s'] = time.perf_counter() - t0
            self.save_model(r, row)
            with open(self.out / 'progress.jsonl', 'a') as f:
                f.write(json.dumps(row) + '\n')
            done.append(row)
            log(f'round {r} done in {row["round_s"]:.0f} s: expert coverage {row["expert_coverage"]:.3f}, '
                f'agreement held out {row["agree_held_before"]:.3f} -> {row["agree_held"]:.3f}; '
                f'model {self.model_path(r)}')
        log(f'{len(done)} rounds in {str(self.out)!r} ({time.perf_counter() - t_run:.0f} s this run)')
        return done


def _first_layout(make, name: str, r: int, tries: int = 20) -> dict:
    """Round r's layout of a hand-made shape: the first layout seed from 100 + 20 r that fits on the table."""
    for seed in range(100 + tries * r, 100 + tries * (r + 1)):
        try:
            return make(name, seed=seed).to_dict()
        except RadError:
            continue
    raise RadError(f'shape {name!r}: none of {tries} layouts fits on the table')


def _pickle(obj, f) -> None:
    pickle.dump(obj, f, protocol=pickle.HIGHEST_PROTOCOL)


def _read_pickle(path: Path):
    # Files this run wrote itself (demonstrations hold numpy arrays, which only pickle keeps exactly).
    with open(path, 'rb') as f:
        return pickle.load(f)

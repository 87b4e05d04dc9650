"""DQN training: determinism, resume after a kill, learning, checkpoints, the CLI.

Tiny budgets and a small network keep each training here to seconds; the real
trainings are scripts (benchmarks/train_agents.sh) whose weights are committed.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from rad_core.env.mdp import TERMINATE, AssemblyEnv, EnvConfig
from rad_core.learning import checkpoint as ckpt
from rad_core.learning.policy import QPolicy
from rad_core.sequencing.decide.actions import action_space
from rad_core.sequencing.decide.episode import Decision, run_episode
from rad_core.training.dataset import Dataset
from rad_core.training.dqn import TrainConfig, Trainer, train
from training import SMALL_NET_FLAGS, tiny, tiny_dataset


@pytest.fixture(scope='module')
def dataset(tmp_path_factory):
    return tiny_dataset(tmp_path_factory.mktemp('data'))


def weights(path) -> dict:
    return torch.load(path, weights_only=True)['weights']


def same_weights(a, b) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_dataset_round_trip(dataset):
    data = Dataset.load(dataset)
    assert len(data) == 24 and data.header['grids'] == [3]
    e = data.entries[0]
    assert e.seed == 1_000_000 and e.placements
    scene = e.scene()
    assert scene.num_target_cells > 0


def test_two_runs_with_one_seed_give_identical_weights_and_another_seed_does_not(dataset, tmp_path):
    for name, seed in (('a', 0), ('b', 0), ('c', 1)):
        train(tiny(dataset, seed=seed), tmp_path / name)
    a, b, c = (weights(tmp_path / n / 'model.pt') for n in 'abc')
    assert same_weights(a, b)
    assert not same_weights(a, c)
    rows = (tmp_path / 'a' / 'progress.csv').read_text().splitlines()
    assert rows[0].startswith('env_steps,grad_steps') and len(rows) == 3
    assert (tmp_path / 'a' / 'curves.png').stat().st_size > 1000
    assert any((tmp_path / 'a' / 'tb').iterdir())


def test_a_killed_run_resumes_and_ends_as_if_never_stopped(dataset, tmp_path):
    """SIGKILL at a random moment after a checkpoint: --resume continues from it,
    and the final weights equal those of a run that was never interrupted."""
    full = tiny(dataset, total_steps=400, eval_every=200)
    train(full, tmp_path / 'straight')
    env = {**os.environ, 'PYTHONUNBUFFERED': '1'}
    args = [sys.executable, '-m', 'rad_core.cli', 'train', '--out', str(tmp_path / 'killed'),
            '--dataset', str(dataset), '--total-steps', '400', '--learning-starts', '40', '--train-every', '2',
            '--target-update', '40', '--batch-size', '8', '--buffer-size', '500', '--eval-every', '200',
            '--eval-scenes', '3', '--checkpoint-every-s', '0.2',
            *SMALL_NET_FLAGS]
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    ckpt_file = tmp_path / 'killed' / 'checkpoint.pt'
    deadline = time.monotonic() + 120
    while not ckpt_file.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(0.5)
    assert proc.poll() is None, 'the run ended before it could be killed'
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    at_kill = torch.load(ckpt_file, weights_only=False)['position']['env_steps']
    assert 0 < at_kill < 400
    done = subprocess.run(args[:6] + ['--resume'], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert same_weights(weights(tmp_path / 'straight' / 'model.pt'), weights(tmp_path / 'killed' / 'model.pt'))


def test_sigint_checkpoints_and_exits_130(dataset, tmp_path):
    args = [sys.executable, '-m', 'rad_core.cli', 'train', '--out', str(tmp_path / 'run'), '--dataset', str(dataset),
            '--total-steps', '100000', '--learning-starts', '40', '--batch-size', '8', '--eval-every', '100000',
            *SMALL_NET_FLAGS]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # Interrupt once training runs (the run folder appears when it starts), not at a fixed
    # time: start-up (torch, pybullet) takes longer than any fixed sleep on a loaded machine.
    deadline = time.monotonic() + 120
    while not (tmp_path / 'run').exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(2)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert 'interrupted, checkpointed' in out
    pos = torch.load(tmp_path / 'run' / 'checkpoint.pt', weights_only=False)['position']
    assert pos['env_steps'] > 0


def greedy_coverage(policy, data, n) -> float:
    covs = []
    for e in data.entries[:n]:
        scene = e.scene()
        env = AssemblyEnv(scene, EnvConfig(stability='physics'))
        space = action_space('milp', env, e.placements)
        rng = np.random.default_rng(0)

        def decide(env, rng):
            actions = space(env)
            if not actions:
                return Decision(TERMINATE)
            s = policy(env, actions, rng)
            k = int(np.argmax(s))
            return Decision(actions[k] if k < len(actions) else TERMINATE)

        covs.append(run_episode(env, decide, rng).coverage)
        env.stability.close()
    return float(np.mean(covs))


def test_a_short_training_beats_a_random_policy_on_its_training_scenes(dataset, tmp_path):
    train(tiny(dataset, total_steps=1500, learning_starts=200, train_every=2, target_update=200, batch_size=16,
               eps_fraction=0.5, lr=1e-3, eval_every=1500), tmp_path / 'run')
    q = QPolicy.load(tmp_path / 'run' / 'model.pt')
    data = Dataset.load(dataset)
    learned = greedy_coverage(q.scores, data, 24)
    uniform = greedy_coverage(lambda env, actions, rng: rng.random(len(actions) + 1), data, 24)
    assert learned > uniform + 0.1, (learned, uniform)


def test_bad_checkpoints_name_the_file_and_the_problem(tmp_path, dataset):
    with pytest.raises(ckpt.CheckpointError, match='does not exist'):
        QPolicy.load(tmp_path / 'missing.pt')
    bad = tmp_path / 'garbage.pt'
    bad.write_bytes(b'not a torch file at all')
    with pytest.raises(ckpt.CheckpointError, match='garbage.pt.*corrupt'):
        QPolicy.load(bad)
    other = tmp_path / 'other.pt'
    torch.save({'format': 'something/9'}, other)
    with pytest.raises(ckpt.CheckpointError, match="other.pt.*format 'something/9'"):
        QPolicy.load(other)
    train(tiny(dataset, total_steps=50, learning_starts=10), tmp_path / 'run')
    doc = torch.load(tmp_path / 'run' / 'model.pt', weights_only=True)
    doc['net']['dim'] = 48
    wrong = tmp_path / 'wrong.pt'
    torch.save(doc, wrong)
    with pytest.raises(ckpt.CheckpointError, match='wrong.pt.*do not fit'):
        QPolicy.load(wrong)
    truncated = tmp_path / 'truncated.pt'
    truncated.write_bytes((tmp_path / 'run' / 'model.pt').read_bytes()[:2000])
    with pytest.raises(ckpt.CheckpointError, match='truncated.pt.*corrupt'):
        QPolicy.load(truncated)
    # Through the CLI: exit 2, one line naming the file, no fallback to another policy.
    r = subprocess.run([sys.executable, '-m', 'rad_core.cli', 'eval', '--agent', 'milp-dqn', '--checkpoint',
                        str(truncated), '--grid', '3', '--scenes', '1'], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and 'truncated.pt' in r.stderr and r.stderr.count('\n') == 1


def test_an_existing_run_is_not_overwritten_and_resume_keeps_its_config(dataset, tmp_path):
    train(tiny(dataset, total_steps=60), tmp_path / 'run')
    with pytest.raises(Exception, match='already holds a training run'):
        train(tiny(dataset, total_steps=60), tmp_path / 'run')
    r = subprocess.run([sys.executable, '-m', 'rad_core.cli', 'train', '--out', str(tmp_path / 'run'), '--resume',
                        '--lr', '0.1'], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and '--lr' in r.stderr
    out = train(TrainConfig(), tmp_path / 'run', resume=True, total_steps=100)
    assert out['env_steps'] >= 100
    # Extending a run keeps its exploration schedule (eps_fraction of the first total_steps).
    pos = torch.load(tmp_path / 'run' / 'checkpoint.pt', weights_only=False)['position']
    assert pos['eps_horizon'] == pytest.approx(0.4 * 60)
    rows = (tmp_path / 'run' / 'progress.csv').read_text().splitlines()[1:]
    steps = [int(r.split(',')[0]) for r in rows]
    assert steps == sorted(set(steps))


def test_config_errors_are_clear():
    with pytest.raises(Exception, match='method must be one of'):
        TrainConfig(method='ppo').validate()
    with pytest.raises(Exception, match='multiple of heads'):
        TrainConfig(dim=30, heads=4).validate()
    with pytest.raises(Exception, match='grad_clip must be a positive'):
        TrainConfig(grad_clip=0).validate()
    with pytest.raises(Exception, match='no CUDA'):
        if torch.cuda.is_available():
            raise RuntimeError('no CUDA (skipped: a GPU is present)')
        Trainer(TrainConfig(device='cuda'), Path('/tmp/unused'))


@pytest.mark.parametrize('name', ['milp-dqn', 'dqn', 'dqn-rel', 'milp-dqn-mixed'])
def test_shipped_agents_load_by_name_and_evaluate_with_the_same_keys(name):
    from rad_core.domain.scene_sources import generated_scenes
    from rad_core.experiment.evaluation import KEYS, evaluate
    assert ckpt.resolve(name).is_file(), f'{name}: no shipped weights in {ckpt.WEIGHTS_DIR}'
    q = QPolicy.load(name)
    assert q.name in name and q.source.endswith(f'{name}.pt')
    result = evaluate(name, generated_scenes(3, 2, 3, 0), robot=False, seed=0)
    assert set(result) == set(KEYS) and result['n'] == 3


def test_verify_never_fails_and_never_builds_less():
    """--verify: the best-ranked action the stability check accepts; a failing action
    is skipped instead of ending the episode."""
    from rad_core.domain.scene_sources import generated_scenes
    from rad_core.experiment.evaluation import evaluate, get_agent
    scenes = list(generated_scenes(4, 2, 12, 0))
    plain = evaluate('milp-dqn', scenes, robot=False, seed=0)
    checked = evaluate(get_agent('milp-dqn', verify=True), scenes, robot=False, seed=0)
    assert checked['f'] == 0
    for a, b in zip(plain['scenes'], checked['scenes']):
        if a['outcome'] != 'invalid_unstable':
            continue
        assert b['coverage'] >= a['coverage'] - 1e-9


def test_a_model_of_another_action_space_is_refused():
    from rad_core.domain.scene_sources import generated_scenes
    from rad_core.experiment.evaluation import evaluate
    with pytest.raises(Exception, match="trained on the 'milp' action space"):
        evaluate('dqn', generated_scenes(3, 2, 1, 0), robot=False, seed=0, policy=QPolicy.load('milp-dqn'))


# ---- with the robot in the loop ---------------------------------------------------------
def robot_tiny(dataset, **kw) -> TrainConfig:
    return tiny(dataset, robot=True, total_steps=200, learning_starts=30, eval_every=100, eval_scenes=2, **kw)


def test_robot_training_runs_checkpoints_and_resumes_as_if_never_stopped(dataset, tmp_path):
    """A few hundred robot steps; stopped after an episode past step 80 (as SIGINT
    does) and resumed, the weights and the step cache equal those of a straight run."""
    cfg = robot_tiny(dataset)
    train(cfg, tmp_path / 'straight')
    rows = (tmp_path / 'straight' / 'progress.csv').read_text().splitlines()
    assert 'eval_failures' in rows[0] and 'cache_hit_rate' in rows[0] and len(rows) == 3
    stopped = Trainer(robot_tiny(dataset), tmp_path / 'stopped')
    result = stopped.run(progress=lambda steps: setattr(stopped, '_stop', steps >= 80))
    assert result['interrupted'] and 80 <= result['env_steps'] < 200
    doc = torch.load(tmp_path / 'stopped' / 'checkpoint.pt', weights_only=False)
    assert doc['step_cache']['table'], 'the checkpoint holds the step cache'
    train(TrainConfig(), tmp_path / 'stopped', resume=True)
    assert same_weights(weights(tmp_path / 'straight' / 'model.pt'), weights(tmp_path / 'stopped' / 'model.pt'))
    a = torch.load(tmp_path / 'straight' / 'checkpoint.pt', weights_only=False)['step_cache']
    b = torch.load(tmp_path / 'stopped' / 'checkpoint.pt', weights_only=False)['step_cache']
    assert a['table'] == b['table']


def test_init_starts_from_the_model_file_and_a_mismatch_is_refused(dataset, tmp_path):
    train(tiny(dataset, total_steps=50, learning_starts=10), tmp_path / 'norobot')
    init = tmp_path / 'norobot' / 'model.pt'
    trainer = Trainer(robot_tiny(dataset, init=str(init)), tmp_path / 'fine')
    assert same_weights(trainer.q.state_dict(), weights(init))
    assert same_weights(trainer.target.state_dict(), weights(init))
    # The shipped no-robot network by name (the default sizes are its sizes).
    shipped = Trainer(TrainConfig(dataset=str(dataset), robot=True, init='milp-dqn-mixed'), tmp_path / 'shipped')
    assert same_weights(shipped.q.state_dict(), weights(ckpt.resolve('milp-dqn-mixed')))
    with pytest.raises(Exception, match='network sizes'):
        Trainer(robot_tiny(dataset, init='milp-dqn-mixed'), tmp_path / 'small')
    with pytest.raises(Exception, match="action space"):
        Trainer(robot_tiny(dataset, method='dqn', init=str(init)), tmp_path / 'dqn')

"""Session set-up for every test: the loopback-only DDS environment, then ROS fixtures.

scripts/test.sh runs pytest with scripts/env.sh sourced. When pytest is started
without it (an IDE, a bare `.venv/bin/python -m pytest`), this file loads env.sh's
settings into os.environ at import time, before any test module can import rclpy,
and then re-executes pytest once so that the dynamic loader also sees the workspace
libraries (generated interfaces import only if LD_LIBRARY_PATH held them at start).

It also sorts the tests into tiers (markers registered in pytest.ini): `dds` for
everything under DDS_DIRS, `slow` for the heavy tests named in SLOW. `make test-fast`
runs `-m "not slow and not dds"`; `make test` runs every tier.
"""

from __future__ import annotations

import os
import sys
import uuid
from pathlib import Path

import pytest
import ros_harness as harness

_REEXEC_GUARD = 'RAD_PYTEST_ENV_LOADED'
_needs_reexec = False

if harness.dds_env_problems(os.environ):
    _loaded = harness.load_env_script()
    _old_ld = set(os.environ.get('LD_LIBRARY_PATH', '').split(':'))
    _needs_reexec = (not os.environ.get(_REEXEC_GUARD)
                     and bool(set(_loaded.get('LD_LIBRARY_PATH', '').split(':')) - _old_ld))
    os.environ.clear()
    os.environ.update(_loaded)

_problems = harness.dds_env_problems(os.environ)
if _problems:
    raise RuntimeError('the loopback-only DDS settings of scripts/env.sh are not in force: '
                       + '; '.join(_problems))
assert 'rclpy' not in sys.modules, 'rclpy was imported before the DDS settings were loaded'

# Test runs side by side on one machine (CI beside a developer's run, two checkouts)
# must not hear each other's nodes: unless RAD_ROS_DOMAIN_ID pins a domain, each
# session takes its own, from the pid (the same after the re-exec above), among 1-101
# without env.sh's default 42. Not above 101: a domain's DDS ports are 7400 + 250 * id
# and up, and from 102 on they fall in Linux's ephemeral range (32768-60999), where the
# kernel hands the same ports to any process's outgoing sockets (ROS 2's domain ID
# guide). Domains 100-199 did that: a session on domain 171 found an ephemeral socket on
# 0.0.0.0:50213 among its DDS ports. RAD_ROS_DOMAIN_ID is set too, so scripts that
# source env.sh (the demo) join it.
_SAFE_DOMAINS = [d for d in range(1, 102) if d != 42]
if not os.environ.get('RAD_ROS_DOMAIN_ID'):
    os.environ['RAD_ROS_DOMAIN_ID'] = os.environ['ROS_DOMAIN_ID'] = str(_SAFE_DOMAINS[os.getpid() % len(_SAFE_DOMAINS)])


def pytest_configure(config):
    if _needs_reexec:
        # Output capture is suspended here, so the new process writes to the terminal.
        capman = config.pluginmanager.getplugin('capturemanager')
        if capman is not None:
            capman.suspend_global_capture(in_=True)
        os.environ[_REEXEC_GUARD] = '1'
        sys.stdout.flush()
        sys.stderr.flush()
        os.execve(sys.executable, sys.orig_argv, dict(os.environ))


# Tests that start nodes, talk over DDS or run the whole graph.
DDS_DIRS = ('tests/nodes', 'tests/ros', 'tests/e2e')

# The heavy tests of the pure-core and message tiers, each with why it is slow and what
# it took (seconds, on the 2 shared cores under a background benchmark). An entry is a
# file or file::function (every parameter case). tests/test_tiers.py checks each exists.
SLOW = (
    ('tests/core/test_dqn.py::test_a_short_training_beats_a_random_policy_on_its_training_scenes',
     'trains a network (18 s)'),
    ('tests/core/test_dqn.py::test_a_killed_run_resumes_and_ends_as_if_never_stopped',
     'trains twice in subprocesses (17 s)'),
    ('tests/core/test_dqn.py::test_robot_training_runs_checkpoints_and_resumes_as_if_never_stopped',
     'trains with the robot in the loop (16 s)'),
    ('tests/core/test_dqn.py::test_sigint_checkpoints_and_exits_130', 'trains in a subprocess (5 s)'),
    ('tests/core/test_dqn.py::test_two_runs_with_one_seed_give_identical_weights_and_another_seed_does_not',
     'trains three times (4 s)'),
    ('tests/core/test_dqn.py::test_an_existing_run_is_not_overwritten_and_resume_keeps_its_config',
     '`rad train` subprocesses (4 s)'),
    ('tests/core/test_dqn.py::test_bad_checkpoints_name_the_file_and_the_problem',
     '`rad eval` subprocesses that import torch (3 s)'),
    ('tests/core/test_dqn.py::test_init_starts_from_the_model_file_and_a_mismatch_is_refused',
     'trains, then builds four trainers (4 s)'),
    ('tests/core/test_dqn.py::test_verify_never_fails_and_never_builds_less',
     'evaluates a network on 12 scenes twice (5 s)'),
    ('tests/core/test_distributed_train.py::test_cli_actors_starts_its_own_loopback_cluster_and_trains',
     'a Dask cluster and training in subprocesses (16 s)'),
    ('tests/core/test_distributed_train.py::test_bad_flag_combinations_are_one_line_errors',
     '8 `rad train` subprocesses that import torch (15 s)'),
    ('tests/core/test_distributed_train.py::test_two_actors_feed_the_learner_which_checkpoints_and_resumes',
     'a Dask cluster training twice (8 s)'),
    ('tests/core/test_distributed_train.py::test_seeds_give_each_seed_the_standalone_run',
     'a Dask cluster and standalone runs (8 s)'),
    ('tests/core/test_distributed_train.py::test_actors_refresh_their_weights_from_the_learner',
     'a Dask cluster (2 s)'),
    ('tests/core/test_distributed.py::test_two_workers_give_exactly_the_serial_rows_and_metrics',
     'Dask clusters (7 s)'),
    ('tests/core/test_distributed.py::test_cli_bad_workers_and_an_unreachable_scheduler_are_one_line_errors',
     '`rad eval` subprocesses waiting on Dask (6 s)'),
    ('tests/core/test_distributed.py::test_cli_workers_and_scheduler_give_the_serial_json',
     'a Dask cluster behind the CLI (3 s)'),
    ('tests/core/test_distributed.py::test_a_worker_killed_mid_run_loses_no_scene_and_counts_none_twice',
     'a Dask cluster (2 s)'),
    ('tests/core/test_distributed.py::test_every_socket_of_the_cluster_is_on_loopback_while_it_runs',
     'a Dask cluster (2 s)'),
    ('tests/core/test_execute.py::test_builds_the_scene_step_by_step_and_documents_it',
     'simulated robot execution (5 s)'),
    ('tests/core/test_execute.py::test_a_grasp_on_nothing_fails_the_step_and_the_loop_replans',
     'simulated robot execution (5 s)'),
    ('tests/core/test_execute.py::test_a_trajectory_aborted_mid_carry_puts_the_block_back_backs_out_and_replans',
     'simulated robot execution (5 s)'),
    ('tests/core/test_execute.py::test_a_block_wedged_on_the_way_back_is_let_go_and_the_arm_backs_out_empty',
     'simulated robot execution (4 s)'),
    ('tests/core/test_execute.py::test_a_block_moved_mid_run_replans_from_the_measured_world',
     'simulated robot execution (3 s)'),
    ('tests/core/test_execute.py::test_cancel_stops_before_the_next_step', 'simulated robot execution (2 s)'),
    ('tests/core/test_faults.py::test_a_block_knocked_on_its_side_is_lost_and_the_run_succeeds_only_if_it_builds_what_was_planned',
     'simulated robot execution (4 s)'),
    ('tests/core/test_faults.py::test_a_slipped_block_falls_and_is_picked_again', 'simulated robot execution (4 s)'),
    ('tests/core/test_faults.py::test_a_neighbour_nudged_a_few_millimetres_is_absorbed',
     'simulated robot execution (2 s)'),
    ('tests/core/test_faults.py::test_a_missed_grasp_opens_backs_out_and_replans', 'simulated robot execution (3 s)'),
    ('tests/core/test_faults.py::test_a_block_left_2mm_into_its_neighbours_cell_is_built_against_not_onto',
     'simulated robot execution (2 s)'),
    ('tests/core/test_faults.py::test_placement_errors_noise_and_dropped_bodies_at_realistic_levels_are_absorbed',
     'simulated robot execution (2 s)'),
    ('tests/core/test_faults.py::test_a_block_found_turned_on_the_table_is_picked_where_it_lies_and_built_straight',
     'simulated robot execution (2 s)'),
    ('tests/core/test_faults.py::test_a_block_pushed_off_its_cell_is_lost_and_its_cells_are_left_out_of_the_plan',
     'simulated robot execution (2 s)'),
    ('tests/core/test_faults.py::test_a_miss_every_time_ends_with_the_reason_after_max_replans',
     'simulated robot execution (2 s)'),
    ('tests/core/test_disassembly.py::test_builds_takes_apart_and_builds_again_with_nothing_touched',
     'simulated robot execution, three times (5 s)'),
    ('tests/core/test_disassembly.py::test_a_block_pushed_aside_mid_take_apart_is_replanned_from_what_is_seen',
     'simulated robot execution (2 s)'),
    ('tests/core/test_evaluation.py::test_heur_fails_with_the_robot_where_heur_verified_does_not',
     'episodes with the robot (4 s)'),
    ('tests/core/test_evaluation.py::test_heur_verified_always_has_the_robot', 'episodes with the robot (2 s)'),
    ('tests/core/test_evaluation.py::test_same_seed_same_numbers_and_the_seed_matters',
     'three evaluations (2 s)'),
    ('tests/core/test_evaluation.py::test_cli_writes_the_json', '`rad eval` subprocess (3 s)'),
    ('tests/core/test_evaluation.py::test_cli_scene_dir_reads_every_file_and_names_a_bad_one',
     '`rad eval` subprocesses (3 s)'),
    ('tests/core/test_evaluation.py::test_execution_mode_reaches_the_robot_env', 'episodes with the robot (2 s)'),
    ('tests/core/test_sequencer.py::test_every_policy_ranks_allocated_actions_and_answers_the_same_twice',
     'every policy, searches included (4 s)'),
    ('tests/core/test_sequencer.py::test_search_agents_with_verification_never_fail_and_are_reproducible',
     'searches with the robot (3 s)'),
    ('tests/core/test_robot_env.py::test_guided_episode_builds_what_the_mdp_books',
     'whole episodes with the robot (4 s)'),
    ('tests/core/test_robot_env.py::test_the_step_cache_replays_the_verdicts_of_a_fresh_env',
     'episodes with the robot, twice (2 s)'),
    ('tests/core/test_trajectory_limits.py::test_planned_scenes_stay_within_both_robots_limits_at_1khz',
     'plans whole scenes with GAMP (2 s)'),
    ('tests/core/test_allocation.py::test_time_limit_is_honoured_and_bound_reported',
     'waits out solver time limits (3 s)'),
    ('tests/core/test_generator.py::test_calibrated_to_the_papers_target_sizes', 'generates hundreds of scenes (2 s)'),
    ('tests/core/test_cli_startup.py::test_train_help_still_lists_the_config_flags',
     '`rad train --help` subprocesses that import torch (7 s)'),
)


def tiers_of(path: str | Path, name: str = '') -> set[str]:
    """The tier markers of the test `name` (function, maybe with [params]) in file `path`."""
    path = Path(path)
    rel = (path.relative_to(harness.REPO_ROOT) if path.is_relative_to(harness.REPO_ROOT) else path).as_posix()
    tiers = set()
    if any(rel.startswith(d + '/') for d in DDS_DIRS):
        tiers.add('dds')
    function = name.split('[')[0]
    if any(entry in (rel, f'{rel}::{function}') for entry, _ in SLOW):
        tiers.add('slow')
    return tiers


def pytest_collection_modifyitems(config, items):
    for item in items:
        for tier in sorted(tiers_of(item.path, item.name)):
            item.add_marker(tier)


def pytest_report_header(config):
    return (f"DDS: domain {os.environ['ROS_DOMAIN_ID']}, "
            f"{os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}, "
            f"profile {os.environ['FASTRTPS_DEFAULT_PROFILES_FILE']}")


@pytest.fixture
def set_down_hand(monkeypatch):
    """The paper's hand, which only sets blocks down: every GAMP config the test makes without saying has
    no drop (`rad_core.gamp.planner.DROP_BY_DEFAULT`). For the tests of what that hand cannot do."""
    from rad_core.gamp import planner

    monkeypatch.setattr(planner, 'DROP_BY_DEFAULT', False)


@pytest.fixture(scope='session')
def rclpy_session():
    """rclpy initialised once for the whole session (the default context)."""
    import rclpy

    rclpy.init()
    yield
    rclpy.try_shutdown()


@pytest.fixture
def ros_node(rclpy_session):
    """A fresh rclpy node in the test process, destroyed after the test."""
    import rclpy

    node = rclpy.create_node(f'rad_test_{uuid.uuid4().hex[:8]}')
    yield node
    node.destroy_node()


@pytest.fixture
def node_process(tmp_path):
    """Factory: node_process(package, executable, *args) starts an installed node.

    Every process still running at the end of the test is stopped (SIGINT, then
    SIGKILL); a test that cares about a clean exit asserts `proc.stop() == 0`.
    Output goes to <tmp_path>/<package>.<executable>.{stdout,stderr}.
    """
    started: list[harness.NodeProcess] = []

    def start(package: str, executable: str, *args: str, env=None) -> harness.NodeProcess:
        proc = harness.start_node(package, executable, *args, log_dir=tmp_path, env=env)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.stop()
        print(proc.output_tail())  # shown by pytest only when the test failed


@pytest.fixture
def process(tmp_path):
    """Factory: process(argv, name=None, env=None) starts any command like node_process."""
    started: list[harness.NodeProcess] = []

    def start(argv, name=None, env=None) -> harness.NodeProcess:
        proc = harness.NodeProcess(list(argv), tmp_path, name=name, env=env)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.stop()
        print(proc.output_tail())


@pytest.fixture(scope='module')
def motion():
    """An in-process GAMP as plans take it (`sequencing.planning.plan.local_motion_planner`), one per test module."""
    from rad_core.gamp.action import MotionPlanner
    from rad_core.sequencing.planning.plan import local_motion_planner
    planner = MotionPlanner()
    yield local_motion_planner(planner)
    planner.close()

"""`ros2 run rad_planner bag`: record, replay and describe a rad run as an MCAP bag (rad_ros.bag).

  bag record -o run.mcap [--topics T ...] [--duration S] [--ros-args ...]
      Records rad's topic set (rad_ros.bag.BAG_TOPICS; latched topics are caught even when published
      before the recorder started) until Ctrl-C / SIGTERM or --duration seconds; the file is finished
      (summary, rosbag2 metadata) either way. Prints 'bag recording: ...' once subscribed and
      'bag recorded: ...' with the counts at the end.
  bag play run.mcap [--rate R] [--clock [HZ]] [--delay S] [--topics T ...] [--hold] [--ros-args ...]
      Publishes the recorded messages with their timing (x R) and their recorded QoS (latched stays
      latched); --clock publishes /clock from the recorded time (HZ, default 40), --hold keeps the
      publishers (and the latched messages) up after the last message until Ctrl-C.
  bag info run.mcap
      Topics, types, message counts, time span.

The files are what `ros2 bag record -s mcap` writes, so `ros2 bag play/info` and Foxglove read them.
Stopping follows rad_ros.node_main: rclpy's signal handlers are off, SIGINT and SIGTERM only set a flag
the loop checks every TICK_S, and the node is torn down after the executor has settled.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time

from rad_ros.bag import BAG_TOPICS, BagError, PlayOptions, Recorder, info, play
from rad_ros.node_main import TICK_S, settle

PROG = 'bag'


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description='Record, replay and describe a rad run (MCAP, '
                                     'readable by ros2 bag and Foxglove).')
    sub = parser.add_subparsers(dest='command', required=True)
    rec = sub.add_parser('record', help='record rad\'s topics into an .mcap file')
    rec.add_argument('-o', '--output', required=True, help='the .mcap file to write')
    rec.add_argument('--topics', nargs='+', metavar='TOPIC',
                     help='topics to record (default: ' + ' '.join(t.name for t in BAG_TOPICS) + ')')
    rec.add_argument('--duration', type=float, default=0.0, metavar='S', help='stop after S seconds (0: at Ctrl-C)')
    rec.add_argument('--force', action='store_true', help='overwrite an existing file')
    ply = sub.add_parser('play', help='publish a recorded run again')
    ply.add_argument('bag', help='the .mcap file')
    ply.add_argument('--rate', type=float, default=1.0, help='playback speed factor (default 1)')
    ply.add_argument('--clock', type=float, nargs='?', const=40.0, default=0.0, metavar='HZ',
                     help='publish /clock from the recorded time, at HZ (default 40)')
    ply.add_argument('--delay', type=float, default=0.0, metavar='S',
                     help='wait S seconds after creating the publishers, for subscribers to match')
    ply.add_argument('--topics', nargs='+', metavar='TOPIC', help='only these recorded topics')
    ply.add_argument('--hold', action='store_true',
                     help='after the last message keep the latched messages served until Ctrl-C')
    inf = sub.add_parser('info', help='describe a bag')
    inf.add_argument('bag', help='the .mcap file')
    return parser


class _Stop:
    """SIGINT and SIGTERM set `event` (rclpy's own handlers stay off, as in rad_ros.node_main)."""

    def __init__(self):
        self.event = threading.Event()
        signal.signal(signal.SIGINT, self._handle)
        signal.signal(signal.SIGTERM, self._handle)

    def _handle(self, signum, frame):
        self.event.set()


def _init(ros_args):
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)


def record(args, ros_args) -> int:
    import rclpy
    from pathlib import Path
    from rclpy.executors import SingleThreadedExecutor

    if Path(args.output).exists() and not args.force:
        raise BagError(f'{args.output} exists; pass --force to overwrite it')
    stop = _Stop()
    _init(ros_args)
    node = rclpy.create_node('rad_bag_recorder')
    executor = SingleThreadedExecutor()
    recorder = None
    try:
        recorder = Recorder(node, args.output, args.topics)
        executor.add_node(node)
        topics = sorted(recorder.subscriptions) + sorted(recorder.pending)
        print(f'bag recording: {len(topics)} topics -> {args.output} ({" ".join(topics)})', flush=True)
        deadline = time.monotonic() + args.duration if args.duration > 0 else None
        while not stop.event.is_set() and rclpy.ok() and (deadline is None or time.monotonic() < deadline):
            executor.spin_once(timeout_sec=TICK_S)
    finally:
        settle(executor)
        if recorder is not None:
            recorder.close()
            counts = recorder.counts()
            print(f'bag recorded: {sum(counts.values())} messages on {len(counts)} topics -> {args.output} '
                  f'({", ".join(f"{t} {n}" for t, n in sorted(counts.items()))})', flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def play_bag(args, ros_args) -> int:
    import rclpy

    summary = info(args.bag)            # a missing or foreign file fails here, before rclpy starts
    stop = _Stop()
    _init(ros_args)
    node = rclpy.create_node('rad_bag_player')
    try:
        print(f'bag playing: {summary.message_count} messages on {len(summary.topics)} topics, '
              f'{summary.duration_s:.1f} s at rate {args.rate}', flush=True)
        options = PlayOptions(rate=args.rate, clock_hz=args.clock, delay_s=args.delay,
                              topics=tuple(args.topics) if args.topics else None)
        published = play(node, args.bag, options, stop.event)
        print(f'bag played: {sum(published.values())} messages'
              + (' (stopped)' if stop.event.is_set() else ''), flush=True)
        if args.hold and not stop.event.is_set():
            print('bag holding the latched topics until Ctrl-C', flush=True)
            stop.event.wait()
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args = []
    if '--ros-args' in argv:
        at = argv.index('--ros-args')
        argv, ros_args = argv[:at], argv[at:]
    args = _parser().parse_args(argv)
    try:
        if args.command == 'record':
            return record(args, ros_args)
        if args.command == 'play':
            return play_bag(args, ros_args)
        print(info(args.bag).format())
        return 0
    except BagError as e:
        print(f'{PROG}: {e}', file=sys.stderr, flush=True)
        return 1


if __name__ == '__main__':
    sys.exit(main())

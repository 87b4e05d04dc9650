#!/usr/bin/env python3
"""A minimal node for harness tests: publishes std_msgs/String on `chatter` and
serves std_srvs/Trigger on `ping`. Written like rad's real nodes (Jazzy main())."""

import sys

from rad_ros.node_main import run_node
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger


class ChatterNode(Node):

    def __init__(self):
        super().__init__('chatter')
        period_s = self.declare_parameter('period_s', 0.05).value
        self.count = 0
        self.publisher = self.create_publisher(String, 'chatter', 10)
        self.timer = self.create_timer(period_s, self.timer_callback)
        self.service = self.create_service(Trigger, 'ping', self.ping_callback)
        print('chatter ready', flush=True)

    def timer_callback(self):
        self.count += 1
        self.publisher.publish(String(data=f'hello {self.count}'))

    def ping_callback(self, request, response):
        response.success = True
        response.message = f'pong after {self.count} messages'
        return response


def main(args=None):
    return run_node(ChatterNode, args)


if __name__ == '__main__':
    sys.exit(main())

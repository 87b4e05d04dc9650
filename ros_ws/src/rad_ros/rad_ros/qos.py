"""QoS profiles the rad nodes share, so a publisher and its subscribers cannot drift apart."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""The latest message only, kept for late subscribers (the scene, the plan): publisher and
subscribers must both use it, a volatile subscriber gets nothing that was sent before it joined."""

"""What the plain rclpy clients (client.py, hostile_client.py) share: spinning their node until
something is true, and calling a service and waiting for its answer. No mexone code."""

from __future__ import annotations

import time

import rclpy


class Waiter:
    """`spin_until` and `call` on one node."""

    def __init__(self, node):
        self.node = node

    def spin_until(self, predicate, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            rclpy.spin_once(self.node, timeout_sec=0.02)
        return bool(predicate())

    def call(self, client, request, timeout: float = 20.0):
        if not client.wait_for_service(timeout_sec=timeout):
            raise SystemExit(f"no service {client.srv_name}")
        future = client.call_async(request)
        self.spin_until(future.done, timeout)
        return future.result()

"""Fixtures for the unit tests of nodes: an rclpy context of their own."""
import pytest
import rclpy


@pytest.fixture
def context():
    """An initialised rclpy context, shut down after the test."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)

"""The runtime: the tick driver, the daemon's loop and Zenoh wiring, safety limits."""

from .controller import Controller, RuntimeConfig, Sample, TickResult

__all__ = ["Controller", "RuntimeConfig", "Sample", "TickResult"]

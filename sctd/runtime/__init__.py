"""The runtime: fixed-rate loop, Zenoh wiring, wire codec, safety limits."""

from .codec import Keys
from .controller import Controller, RuntimeConfig, Sample, TickResult
from .zsession import make_config, open_session

__all__ = ["Controller", "Keys", "RuntimeConfig", "Sample", "TickResult", "make_config",
           "open_session"]

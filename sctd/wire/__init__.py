"""The wire contract, below every layer that talks over Zenoh (runtime, simulator,
services, tools): the key expressions (:mod:`.keys`), the message codec (:mod:`.codec`),
sessions with sctd's loopback defaults (:mod:`.session`) and the asking side of the
contract's queryables (:mod:`.client`). Its one dependency inside sctd is the skill
bundle that a swap carries."""

from .keys import DEFAULT_ROBOT, Keys

__all__ = ["DEFAULT_ROBOT", "Keys"]

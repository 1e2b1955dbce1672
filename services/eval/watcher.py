"""What a real-time trial's evaluator sees, from the wire: :class:`TrialWatcher` keeps the
newest hand pose, objects, scene, mode, input and daemon status it hears, and gives them
as the :class:`~sctd_services.user.Observation` a :class:`~.trial.TrialRecorder` judges
(``sctd eval``'s real-time trials, ``sctd bench link``'s trials across hosts)."""

from __future__ import annotations

import threading
import time
from typing import Any

import zenoh

from sctd import se3
from sctd.task import Task
from sctd.wire import Keys, codec
from sctd_services.simulated_user import task_frames
from sctd_services.user import Observation

WATCH_RATE = 100.0  # Hz at which the evaluator samples what it sees
# The evaluator keeps only the newest state and target, which it reads at WATCH_RATE: Zenoh
# drops the rest of their 1 kHz on arrival (its downsampling, before any Python callback),
# so that watching does not take from the simulator, the daemon and the user the CPU they
# need to keep real time on a small machine.
WATCH_INGRESS = 250.0  # Hz
SCENE_PERIOD = 0.1  # s between the simulator's scene messages (``sctd sim``'s default)


class TrialWatcher:
    def __init__(self, s: zenoh.Session, task: Task):
        k = Keys()
        self.lock = threading.Lock()
        self.T_world_ee: Any = None
        self.objects: dict[str, Any] = {}
        self.scene: dict[str, Any] = {}
        self._scene_at = (0.0, 0.0)  # (simulated t, monotonic arrival) of the newest scene
        self._t_sim = 0.0  # the newest simulated time an observation carried
        self.mode: str | None = None
        self.u: tuple[float, ...] = (0.0, 0.0, 0.0)
        self.buttons: tuple[int, ...] = (0, 1, 0)
        self.status: dict[str, Any] = {}
        self.inputs = 0
        self.subs = [s.declare_subscriber(key, cb) for key, cb in (
            (k.state, self._state), (k.scene, self._scene), (k.target, self._target),
            (k.input("*"), self._input), (k.status, self._status))]
        self.frames = task_frames(task)
        self.subs += [s.declare_subscriber(k.objects(n), self._object) for n in self.frames]

    def _state(self, sample: zenoh.Sample) -> None:
        try:
            self.T_world_ee = se3.transform_from_pose(codec.decode_state(sample.payload.to_bytes()).pose)
        except codec.DecodeError:
            pass

    def _object(self, sample: zenoh.Sample) -> None:
        try:
            pose = codec.decode_object(sample.payload.to_bytes()).pose
        except codec.DecodeError:
            return
        self.objects[str(sample.key_expr).rsplit("/", 1)[-1]] = se3.transform_from_pose(pose)

    def _scene(self, sample: zenoh.Sample) -> None:
        try:
            scene = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        t = scene.get("t")
        if isinstance(t, (int, float)) and not isinstance(t, bool):
            self._scene_at = (float(t), time.monotonic())
        self.scene = scene

    def sim_time(self) -> float:
        """The simulator's time now: its newest scene's ``t`` plus the wall time since it
        arrived (at most a scene period), never going back."""
        t, arrived = self._scene_at
        self._t_sim = max(self._t_sim, t + min(time.monotonic() - arrived, SCENE_PERIOD))
        return self._t_sim

    def _target(self, sample: zenoh.Sample) -> None:
        try:
            self.mode = codec.decode_target(sample.payload.to_bytes())["state"]
        except codec.DecodeError:
            pass

    def _input(self, sample: zenoh.Sample) -> None:
        try:
            m = codec.decode_input(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        self.u, self.buttons = m.u, m.buttons or (0, 1, 0)
        self.inputs += 1

    def _status(self, sample: zenoh.Sample) -> None:
        try:
            self.status = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            pass

    def observation(self) -> Observation | None:
        if (self.T_world_ee is None or self.mode is None or "t" not in self.scene
                or any(n not in self.objects for n in self.frames)):
            return None
        idle = "mode_button" in self.status and self.status["mode_button"] is None  # nothing to switch
        return Observation(self.sim_time(), self.T_world_ee, dict(self.objects), dict(self.scene), self.mode,
                           switches=not (idle and self.status.get("state") == self.mode))

    def close(self) -> None:
        for sub in self.subs:
            sub.undeclare()

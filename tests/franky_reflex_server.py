"""franky-sim with a reflex on demand: the arm's safety stopping a motion, which franky-sim
does not simulate. ``python -m tests.franky_reflex_server HOST``; each SIGUSR1 aborts the
running motion as a real FR3's reflex does on the wire: the Move command's reply is
``kReflexAborted`` and the arm goes idle, holding where it is (libfranka then raises its
ControlException). franky-sim's own automatic error recovery clears it.
"""

from __future__ import annotations

import signal
import sys
import threading

from franky_sim import SimulationServer
from franky_sim.franka_robot_protocol import MoveStatus, RobotCommand
from franky_sim.franka_server import BaseCommand
from franky_sim.mujoco_simulator import MujocoSimulator


def main(host: str) -> int:
    reflex, stop = threading.Event(), threading.Event()
    signal.signal(signal.SIGUSR1, lambda *a: reflex.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    with MujocoSimulator(enable_visualization=False) as sim:
        sim.add_robot()
        with SimulationServer(sim, hostname_candidates=[host]) as server:
            print(f"reflex server on {host}", flush=True)
            while not stop.is_set():
                if reflex.is_set():
                    reflex.clear()
                    rs = server.robot_servers[0]
                    motion = rs.current_motion_id
                    if motion:
                        BaseCommand.send_response(rs._tcp_socket, RobotCommand.kMove, motion,
                                                  MoveStatus.kReflexAborted)
                        rs.stop_motion(send_preemption_signal=False)
                        rs.reset_current_motion_id()
                        print(f"reflex: motion {motion} aborted", flush=True)
                server.run_once()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))

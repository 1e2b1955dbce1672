"""sctd services: the long-running programs around the runtime.

- :mod:`sctd_services.user` and :mod:`sctd_services.simulated_user`: the simulated user
  (task intents, the device model it learns, human limits) and its Zenoh input client;
- :mod:`sctd_services.eval`: evaluations of skills with the simulated user (lockstep
  trials, the recorder of a trial, the figures); the real-time trial, which starts
  processes, is the application layer's (:mod:`sctd.cli.eval_realtime`);
- :mod:`sctd_services.view`: a skill and its task's scene as shapes, drawn in the browser
  with Viser (``sctd inspect --view``);
- :mod:`sctd_services.record`: the demonstration recorder (``sctd record``), against the
  simulator or any robot that publishes the wire contract.

They sit above the simulator and the runtime and below the ``sctd`` command line
(``docs/architecture.md``).
"""

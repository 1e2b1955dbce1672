"""``sctd robot NAME``: any robot driver (:mod:`sctd.robots`) served on the wire, and the
drivers that are not simulators (``franky``, a Franka FR3 through libfranka's
protocol). docs/robots.md."""

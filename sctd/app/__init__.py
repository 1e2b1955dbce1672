"""What every sctd program shares at its edge, defined once: flags derived from
dataclass fields (:mod:`.options`), the shared robot and Zenoh flags, and how a program
reports a problem and exits (:mod:`.errors`). The runtime, the simulator, the services,
the command line and the benches all take them from here; the pure core (``se3``,
``skill``, ``learn``) parses no arguments and does not import it."""

from .errors import EXIT_CODES, EXIT_FAILED, EXIT_FORCED, EXIT_OK, EXIT_USAGE, Parser, fail
from .options import (
    SKILL_HELP,
    TASK_HELP,
    add_arguments,
    add_deprecated_alias,
    add_robot_argument,
    add_task_argument,
    add_zenoh_arguments,
    check_ranges,
    field_of,
    flag_name,
    from_namespace,
)

__all__ = ["EXIT_CODES", "EXIT_FAILED", "EXIT_FORCED", "EXIT_OK", "EXIT_USAGE", "SKILL_HELP", "TASK_HELP",
           "Parser", "add_arguments", "add_deprecated_alias", "add_robot_argument", "add_task_argument",
           "add_zenoh_arguments", "check_ranges", "fail", "field_of", "flag_name", "from_namespace"]

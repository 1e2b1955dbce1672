"""``sctd learn`` and ``sctd dtw``: the application layer around :mod:`sctd.learn`.

:mod:`.command` parses arguments and reports; :mod:`.report` writes the skill files,
``summary.json`` and the figures of :mod:`.plots`.
"""

from .command import add_dtw_arguments, add_learn_arguments, main_dtw, main_learn, parse_frame

__all__ = ["add_dtw_arguments", "add_learn_arguments", "main_dtw", "main_learn", "parse_frame"]

"""The one error kind of a study's files and answers."""

from __future__ import annotations


class StudyError(ValueError):
    """A plan, an answer or a study folder sctd will not take: ``where: what is wrong``
    (where: the file and field, or the participant, condition, task and item)."""

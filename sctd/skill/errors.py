"""Errors raised when a skill or a model file does not validate."""

from __future__ import annotations


class SkillError(ValueError):
    """A skill failed to validate: ``file: path.to.field: what is wrong``."""

    def __init__(self, file: str, path: str, problem: str):
        self.file = file
        self.path = path
        self.problem = problem
        where = f"{file}: {path}" if path else file
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):  # picklable (the daemon validates bundles in a child process)
        return (type(self), (self.file, self.path, self.problem))

"""Tasks as files: what the project knows of a daily-living task (its scene, how it is
judged), read from a YAML file that names no skill (``docs/tasks.md``).

:func:`find_task` resolves a name or a path (:mod:`.catalog`); :class:`Task` is what a
file says (:mod:`.model`); :class:`TaskError` names the file, the field and the problem;
:func:`handle_pose` is where a joint has moved its handle (:mod:`.kinematics`);
:func:`dump_task` writes a task's file back (:mod:`.writer`).
"""

from .catalog import add_to_path, find_task, known_tasks, load_task, shipped_folder, task_for_object
from .kinematics import handle_jacobian, handle_pose
from .model import Task
from .reader import TaskError, task_from_document
from .writer import dump_task, task_to_yaml

__all__ = ["Task", "TaskError", "add_to_path", "dump_task", "find_task", "handle_jacobian", "handle_pose",
           "known_tasks", "load_task", "shipped_folder", "task_for_object", "task_from_document",
           "task_to_yaml"]

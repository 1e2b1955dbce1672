"""The skill's view as one HTML file: what ``sctd inspect SKILL --view`` shows, kept with
a learner's report and opened later in any browser, from the disk, with no sctd running.

The page is Viser's own client with the scene recorded into it (Viser's scene
serializer, ``as_html``): the skill in its object's frame, the demonstrations coloured
by state, the task's bodies, and the states one after the other, :data:`STATE_SECONDS`
each, on the page's timeline (play, pause, scrub: the timeline is the state picker). A
label over the object names the state shown. The scene tree (the page's tree button)
shows and hides any element. The page loads nothing from anywhere: the client and the
scene are inside it.
"""

from __future__ import annotations

import contextlib
import io

from sctd.learn.demos import Demo
from sctd.skill import Skill
from sctd.task import task_for_object

from .draw import SkillView
from .skill_scene import skill_scene

STATE_SECONDS = 4.0  # s each state is shown on the page's timeline


def skill_page(skill: Skill, demos: list[Demo] | None = None) -> str:
    """The HTML page of ``skill`` (with ``demos``, object frame, if given).

    Raises
    ------
    sctd_sim.view.ViewerUnavailable
        Viser is not installed.
    """
    from sctd_sim.view import stop_server, viser_server

    scene = skill_scene(skill, demos)
    quiet = io.StringIO()  # viser's banner: nothing is served to anyone
    with contextlib.redirect_stderr(quiet), contextlib.redirect_stdout(quiet):
        server = viser_server(0)
    try:
        view = SkillView(server, scene, task=task_for_object(skill.object))
        names = [st.name for st in scene.states]
        label = server.scene.add_label("/skill/shown", "", position=(0.0, 0.0, _label_height(view)))
        view.show(names[0])
        label.text = _title(skill, names, 0)
        recording = server.get_scene_serializer()
        for k in range(1, len(names)):
            recording.insert_sleep(STATE_SECONDS)
            view.show(names[k])
            label.text = _title(skill, names, k)
        recording.insert_sleep(STATE_SECONDS)
        return recording.as_html()
    finally:
        with contextlib.redirect_stderr(quiet), contextlib.redirect_stdout(quiet):
            stop_server(server)


def _title(skill: Skill, names: list[str], k: int) -> str:
    return f"{skill.name}: state {names[k]} ({k + 1} of {len(names)})"


def _label_height(view: SkillView) -> float:
    """Over the drawing (object frame): a little above the highest point drawn."""
    return float(max(0.15, view.look_at[2] + 0.25)) if view.look_at is not None else 0.3

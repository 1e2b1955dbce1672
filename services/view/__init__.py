"""The view: a skill, the arm and the task in 3D, in the browser.

- :mod:`.skill_scene`: a skill as plain shapes in its task object's frame, per state;
- :mod:`.draw`: those shapes on a Viser scene, with a state picker.
"""

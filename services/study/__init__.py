"""``sctd study``: a user study of shared control with people (``docs/study.md``).

The plan (:mod:`.plan`, counterbalanced by :mod:`.latin`), the questionnaires and their
scoring (:mod:`.questionnaires`), the study folder and its crash-safe writer
(:mod:`.store`), the statistics (:mod:`.stats`) and the report (:mod:`.report`; figures
in :mod:`.figures`). :mod:`.conditions` resolves the names a plan holds and says what runs
for a block; :mod:`.simulate` fills a folder with simulated participants. Only the light
modules are re-exported here (no simulator, no matplotlib).
"""

from .errors import StudyError
from .latin import williams_rows
from .plan import Block, Condition, Plan, Schedule, Step, make_plan, plan_from_yaml, plan_to_yaml
from .questionnaires import check_answers, check_participant_id, raw_tlx, sus_score
from .stats import describe, holm, paired_test
from .store import COLUMNS, Progress, StudyStore, TrialRow, Trials, read_trials

__all__ = ["COLUMNS", "Block", "Condition", "Plan", "Progress", "Schedule", "Step", "StudyError",
           "StudyStore", "TrialRow", "Trials", "check_answers", "check_participant_id", "describe", "holm",
           "make_plan", "paired_test", "plan_from_yaml", "plan_to_yaml", "raw_tlx", "read_trials",
           "sus_score", "williams_rows"]

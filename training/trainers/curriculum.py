"""Curricula without demonstrations: stages of environment overrides, promoted by success.

A training config's ``curriculum:`` block (``training/trainers/ppo.py``)::

    curriculum:
      stages: [{n_modules: 12}, {n_modules: 24}, {n_modules: 40}]   # each over the config's env
      promote_at: 0.8        # success rate over the last `window` episodes that moves to the next stage
      window: 50

Training starts at stage 0; when the success rate of the last ``window`` episodes that ended
in the current stage reaches ``promote_at``, the next stage's worlds replace the current ones
(every world starts a new episode; a stage may change the number of modules). The last stage
is kept to the end. The stage reached is logged (``curriculum/stage``) and saved with each
checkpoint, and ``--resume`` continues from it. Stages may change any environment setting
except those that change the observation encoding (``obs_radius``): the network's inputs stay
the same across stages.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from proteo_env.config import ConfigError

KEYS = ("stages", "promote_at", "window")


class Curriculum:
    """The stages of a ``curriculum:`` block and the success record that promotes them.

    Args:
        block: the config's ``curriculum`` mapping (:data:`KEYS`).
        check_env: called with each stage's full overrides; raises for a value the task refuses.
        stage: the stage to start at (a resumed run's).
    """

    def __init__(self, block: dict, check_env, stage: int = 0):
        if not isinstance(block, dict) or set(block) - set(KEYS) or "stages" not in block:
            unknown = sorted(set(block) - set(KEYS)) if isinstance(block, dict) else block
            raise ConfigError(
                f"curriculum: {unknown or 'no stages'!r} is not allowed; allowed: a mapping with "
                f"stages (a list of env overrides), promote_at, window"
            )
        self.stages = block["stages"]
        if not isinstance(self.stages, list) or not self.stages or not all(isinstance(s, dict) for s in self.stages):
            raise ConfigError(
                f"curriculum.stages={self.stages!r} is not allowed; allowed: a non-empty list of "
                "mappings of env overrides"
            )
        self.promote_at = block.get("promote_at", 0.8)
        if not isinstance(self.promote_at, (int, float)) or not 0.0 < self.promote_at <= 1.0:
            raise ConfigError(f"curriculum.promote_at={self.promote_at!r} is not allowed; allowed: a number in (0, 1]")
        self.window = block.get("window", 50)
        if not isinstance(self.window, int) or self.window < 1:
            raise ConfigError(f"curriculum.window={self.window!r} is not allowed; allowed: an integer >= 1")
        for i, overrides in enumerate(self.stages):
            if "obs_radius" in overrides:
                raise ConfigError(
                    f"curriculum stage {i}: obs_radius is not allowed; allowed: settings that keep "
                    "the observation encoding"
                )
            try:
                check_env(overrides)
            except (ValueError, TypeError, KeyError) as err:
                raise ConfigError(f"curriculum stage {i} ({overrides}): {err}") from None
        if not 0 <= stage < len(self.stages):
            raise ConfigError(f"curriculum stage {stage} is not allowed; allowed: 0..{len(self.stages) - 1}")
        self.stage = stage
        self.recent: deque = deque(maxlen=self.window)

    def overrides(self, env: dict) -> dict:
        """The env overrides of the current stage (``env`` with the stage's settings over it)."""
        return {**env, **self.stages[self.stage]}

    def record(self, episodes: list[dict]) -> bool:
        """Count the ended ``episodes`` (``{"success": bool, ...}``); True when they promote the
        curriculum to its next stage (the record then starts afresh)."""
        self.recent.extend(bool(e["success"]) for e in episodes)
        if (
            self.stage + 1 < len(self.stages)
            and len(self.recent) == self.window
            and np.mean(self.recent) >= self.promote_at
        ):
            self.stage += 1
            self.recent.clear()
            return True
        return False

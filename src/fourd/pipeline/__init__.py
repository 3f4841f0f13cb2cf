"""``fourd.pipeline``: stages of a reconstruction mapped over frames by a scheduler (issue 56;
DESIGN.md, "Growing past one machine"): :mod:`~fourd.pipeline.scheduler`."""

from fourd.pipeline.scheduler import SCHEDULERS, check_scheduler, map_frames

__all__ = ["SCHEDULERS", "check_scheduler", "map_frames"]

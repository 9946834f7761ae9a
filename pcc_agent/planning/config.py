"""Where the planner's settings used to live: :class:`PlannerConfig` is in :mod:`pcc_agent.config`.

Kept so that ``from pcc_agent.planning.config import PlannerConfig`` still works; new code
imports it from :mod:`pcc_agent.config` or :mod:`pcc_agent.planning`.
"""

from pcc_agent.config import PlannerConfig

__all__ = ["PlannerConfig"]

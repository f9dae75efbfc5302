"""Campaign engine: plans executed over a persisted cursor, stability decisions, device faults.

Public entry points: :class:`service.engine.manager.CampaignManager` (the
service's runner loop), :class:`service.engine.runner.CampaignRunner` (one
campaign on given devices), :mod:`service.engine.stability` and
:mod:`service.engine.quality` (pure decision functions). See docs/engine.md.
"""

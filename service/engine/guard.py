"""Device calls with retry, suspension and a suspend limit (bluesky-style suspenders).

Every device call of the runner goes through :meth:`DeviceGuard.call`:

1. a retryable :class:`drivers.faults.DeviceFault` is retried with exponential
   back-off on the campaign clock (``retry_attempts`` tries);
2. if it still fails, the campaign is *suspended*: it stays ``running`` with
   ``suspended_reason`` set (``on_suspend``), and the call is retried every
   ``suspend_poll_s`` until the device answers (``on_resume``), like a
   bluesky suspender;
3. suspended for longer than ``suspend_limit_s`` (campaign clock), or a
   non-retryable fault: :class:`CampaignFailed`.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import TypeVar

from drivers.clock import Clock
from drivers.faults import DeviceFault

T = TypeVar("T")


class CampaignFailed(Exception):
    """The campaign cannot continue; the message goes to ``campaign.error``."""


class AbortRequested(Exception):
    """Raised out of a wait when the operator asked to abort (handled by the runner)."""


@dataclass
class FaultPolicy:
    retry_attempts: int = 4
    retry_backoff_s: float = 1.0
    suspend_poll_s: float = 30.0
    suspend_limit_s: float = 1800.0


class DeviceGuard:
    """Wraps device coroutines; counts faults for the steps log and tests."""

    def __init__(
        self,
        clock: Clock,
        policy: FaultPolicy,
        on_suspend: Callable[[str], None],
        on_resume: Callable[[], None],
        check_abort: Callable[[], bool] = lambda: False,
    ) -> None:
        self.clock = clock
        self.policy = policy
        self.on_suspend = on_suspend
        self.on_resume = on_resume
        self.check_abort = check_abort
        self.faults_retried = 0
        self.suspensions = 0

    async def call(self, label: str, fn: Callable[[], Awaitable[T]]) -> T:
        """``await fn()`` with the fault policy; ``label`` names the call in messages."""
        last: DeviceFault | None = None
        delay_s = self.policy.retry_backoff_s
        for _ in range(max(1, self.policy.retry_attempts)):
            try:
                return await fn()
            except DeviceFault as exc:
                if not exc.retryable:
                    raise CampaignFailed(f"{label}: {exc}") from exc
                last = exc
                self.faults_retried += 1
                await self.clock.sleep(delay_s)
                delay_s *= 2.0
        assert last is not None
        return await self._suspended(label, fn, last)

    async def _suspended(self, label: str, fn: Callable[[], Awaitable[T]],
                         fault: DeviceFault) -> T:
        self.suspensions += 1
        since_s = self.clock.now()
        self.on_suspend(f"{label}: {fault}")
        while True:
            if self.check_abort():
                raise AbortRequested(label)
            if self.clock.now() - since_s >= self.policy.suspend_limit_s:
                raise CampaignFailed(
                    f"{label}: device did not recover within {self.policy.suspend_limit_s:.0f} s "
                    f"(last fault: {fault})"
                )
            await self.clock.sleep(self.policy.suspend_poll_s)
            try:
                result = await fn()
            except DeviceFault as exc:
                if not exc.retryable:
                    raise CampaignFailed(f"{label}: {exc}") from exc
                fault = exc
                continue
            self.on_resume()
            return result

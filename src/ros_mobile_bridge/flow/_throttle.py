"""The adaptive throttle: caps a subscription's delivery rate by the event
loop's lag, ahead of decoding.

A throttle curve is a tuple of :class:`Bucket` ordered by increasing lag
threshold. The deeper the bucket (the higher the lag), the longer the minimum
interval between delivered messages. Three curves ship, one per
:data:`ThrottleMode`:

=============  =========================================================
mode           curve (lag threshold ms -> min interval ms, label)
=============  =========================================================
performance    0 -> 0 "full rate", 50 -> 33 "30 Hz", 120 -> 66 "15 Hz",
               250 -> 100 "10 Hz", 500 -> 250 "4 Hz"
auto           0 -> 0 "full rate", 30 -> 50 "20 Hz", 80 -> 100 "10 Hz",
               150 -> 250 "4 Hz", 300 -> 1000 "1 Hz"
efficient      0 -> 100 "10 Hz", 20 -> 200 "5 Hz", 50 -> 500 "2 Hz",
               100 -> 1000 "1 Hz", 200 -> 2000 "0.5 Hz"
=============  =========================================================

``performance`` tolerates more lag before it caps, and caps mildly (a
desktop with headroom); ``efficient`` is capped from the start and caps hard
(a phone on battery); ``auto`` sits between. A client may replace any curve
(:func:`resolve_presets`).

The rules (:class:`AdaptiveThrottle`): tighten at once on the lag that
recurs (at least three samples of the last second reached it), relax on the
4-second 90th-percentile lag with a deadband, and always jump straight to
the justified bucket. One stall never tightens: the frames that queued up
behind it already crossed the socket, and dropping them saves nothing.
Every change of bucket is logged at INFO with the topic, the old and new
interval and the lag that caused it.
"""

from __future__ import annotations

import bisect
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType
from typing import Final, Literal, NamedTuple, Protocol, get_args

from ._lag import LagMonitor

__all__ = [
    "DEFAULT_PRESETS",
    "THROTTLE_MODES",
    "AdaptiveThrottle",
    "Bucket",
    "LagSource",
    "ThrottleMode",
    "resolve_presets",
]

ThrottleMode = Literal["performance", "auto", "efficient"]
"""Which throttle curve applies: ``"performance"`` (tolerant), ``"auto"``
(the default) or ``"efficient"`` (capped from the start)."""

THROTTLE_MODES: Final[tuple[ThrottleMode, ...]] = get_args(ThrottleMode)


class Bucket(NamedTuple):
    """One step of a throttle curve: from ``threshold_ms`` of event-loop lag
    upwards, deliver at most one message per ``min_interval_ms`` (0 = no
    cap). ``label`` names the step for display (``"10 Hz"``). A plain
    ``(threshold_ms, min_interval_ms, label)`` tuple is accepted wherever a
    curve is given."""

    threshold_ms: float
    min_interval_ms: float
    label: str


DEFAULT_PRESETS: Final[Mapping[ThrottleMode, tuple[Bucket, ...]]] = MappingProxyType(
    {
        "performance": (
            Bucket(0.0, 0.0, "full rate"),
            Bucket(50.0, 33.0, "30 Hz"),
            Bucket(120.0, 66.0, "15 Hz"),
            Bucket(250.0, 100.0, "10 Hz"),
            Bucket(500.0, 250.0, "4 Hz"),
        ),
        "auto": (
            Bucket(0.0, 0.0, "full rate"),
            Bucket(30.0, 50.0, "20 Hz"),
            Bucket(80.0, 100.0, "10 Hz"),
            Bucket(150.0, 250.0, "4 Hz"),
            Bucket(300.0, 1000.0, "1 Hz"),
        ),
        "efficient": (
            Bucket(0.0, 100.0, "10 Hz"),
            Bucket(20.0, 200.0, "5 Hz"),
            Bucket(50.0, 500.0, "2 Hz"),
            Bucket(100.0, 1000.0, "1 Hz"),
            Bucket(200.0, 2000.0, "0.5 Hz"),
        ),
    }
)
"""The shipped curves, read-only. Build on them rather than mutate them."""


# -- validation ----------------------------------------------------------------------
def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def _validate_curve(curve: object) -> tuple[tuple[Bucket, ...], None] | tuple[None, str]:
    """The curve as buckets, or the reason it is invalid."""
    if isinstance(curve, str | bytes) or not isinstance(curve, Sequence):
        return None, f"a curve must be a sequence of buckets, not {type(curve).__name__}"
    if not curve:
        return None, "the curve is empty"
    buckets: list[Bucket] = []
    for position, entry in enumerate(curve):
        if isinstance(entry, str | bytes) or not isinstance(entry, Sequence) or len(entry) != 3:
            return None, (
                f"bucket {position} must be (threshold_ms, min_interval_ms, label), got {entry!r}"
            )
        threshold, interval, label = _number(entry[0]), _number(entry[1]), entry[2]
        if threshold is None:
            return None, f"bucket {position}: threshold_ms must be a finite number"
        if interval is None:
            return None, f"bucket {position}: min_interval_ms must be a finite number"
        if not isinstance(label, str):
            return None, f"bucket {position}: label must be a str, not {type(label).__name__}"
        if interval < 0:
            return None, f"bucket {position}: min_interval_ms must be >= 0, got {interval}"
        if position == 0:
            if threshold != 0:
                return None, f"the first threshold_ms must be 0, got {threshold}"
        else:
            previous = buckets[-1]
            if threshold <= previous.threshold_ms:
                return None, (
                    f"thresholds must increase strictly: bucket {position} has "
                    f"{threshold} after {previous.threshold_ms}"
                )
            if interval < previous.min_interval_ms:
                return None, (
                    f"min intervals must not decrease: bucket {position} has "
                    f"{interval} after {previous.min_interval_ms}"
                )
        buckets.append(Bucket(threshold, interval, label))
    return tuple(buckets), None


def resolve_presets(
    overrides: Mapping[str, Sequence[Bucket | tuple[float, float, str]]] | None,
    logger: logging.Logger,
) -> dict[ThrottleMode, tuple[Bucket, ...]]:
    """The curve of every mode: :data:`DEFAULT_PRESETS` with ``overrides``
    applied. Called once, when a client is built.

    A curve is valid when it is non-empty, its first threshold is 0, its
    thresholds increase strictly, its intervals are finite, non-negative and
    never decrease, and its labels are ``str``. An invalid curve is logged as
    a WARNING on ``logger`` (naming the mode and the reason) and that mode
    keeps its default curve; the other modes' overrides still apply.

    Raises ``ValueError`` for a mode name that is not a :data:`ThrottleMode`
    (a typo would otherwise be silently ignored) and ``TypeError`` when
    ``overrides`` is not a mapping."""
    resolved: dict[ThrottleMode, tuple[Bucket, ...]] = dict(DEFAULT_PRESETS)
    if overrides is None:
        return resolved
    if not isinstance(overrides, Mapping):
        raise TypeError(
            f"throttle preset overrides must be a mapping of mode to curve, "
            f"not {type(overrides).__name__}"
        )
    unknown = [mode for mode in overrides if mode not in THROTTLE_MODES]
    if unknown:
        raise ValueError(
            f"unknown throttle mode(s) in preset overrides: {', '.join(map(repr, unknown))}; "
            f"expected one of {', '.join(map(repr, THROTTLE_MODES))}"
        )
    for mode in THROTTLE_MODES:
        if mode not in overrides:
            continue
        curve, reason = _validate_curve(overrides[mode])
        if curve is None:
            logger.warning(
                "throttle preset override for mode %r ignored (%s); using the default curve",
                mode,
                reason,
            )
        else:
            resolved[mode] = curve
    return resolved


# -- the throttle -----------------------------------------------------------------------
class LagSource(Protocol):
    """What the throttle reads: both signals in ms, O(1) (see
    :class:`~ros_mobile_bridge.flow._lag.LagMonitor`)."""

    def recurring_lag_ms(self) -> float: ...

    def sustained_lag_ms(self) -> float: ...


class AdaptiveThrottle:
    """Chooses a subscription's minimum delivery interval from the event
    loop's lag.

    ``presets`` maps every mode to a valid curve (from
    :func:`resolve_presets`). ``mode`` is a mode, or a callable read on
    every :meth:`interval_s` call, so a settings change applies to the next
    message; an unknown mode value falls back to ``"auto"`` (warned once per
    value on ``logger``).

    The rules, where a curve's bucket *justified* by a lag is the deepest
    whose threshold is at most that lag:

    - TIGHTEN at once: when ``max(recurring_lag, sustained_lag)`` justifies
      a deeper bucket than the current one, jump straight to it. Both
      signals need at least three samples at a lag, so a single stall
      (user code blocking the loop once, a decoder build) never tightens.
    - RELAX with a deadband: only when ``sustained_lag`` is at least
      ``deadband_ms`` below the current bucket's threshold, then jump
      straight to the bucket justified by ``max(recurring_lag,
      sustained_lag)``.
    - On a mode change, the new curve's justified bucket applies at once.

    So the chosen bucket ``i`` always satisfies
    ``justified(max(recurring, sustained)) <= i <=
    justified(max(recurring, sustained + deadband_ms))``: never shallower
    than the lag justifies, and deeper only by the deadband's hysteresis,
    which stops hunting when the lag hovers around a threshold.

    ``name`` (the topic) labels the INFO line logged on ``logger`` at every
    change of bucket or mode.

    :meth:`interval_s` is O(1) in the common case (the lag signals change
    about every 50 ms; between changes the last answer is reused). With a
    fixed mode over a :class:`~ros_mobile_bridge.flow._lag.LagMonitor` it
    reads nothing until the monitor's ``generation`` moves (a new
    sample): one comparison per call. The properties describe the state as
    of the last :meth:`interval_s` call (or construction)."""

    def __init__(
        self,
        presets: Mapping[ThrottleMode, Sequence[Bucket]],
        mode: ThrottleMode | Callable[[], ThrottleMode],
        lag: LagSource,
        *,
        deadband_ms: float = 10.0,
        logger: logging.Logger | None = None,
        name: str = "",
    ) -> None:
        self._name = name
        deadband = _number(deadband_ms)
        if deadband is None or deadband < 0:
            raise ValueError(f"deadband_ms must be a finite number >= 0, got {deadband_ms!r}")
        curves: dict[ThrottleMode, tuple[Bucket, ...]] = {}
        for mode_name in THROTTLE_MODES:
            if mode_name not in presets:
                raise ValueError(f"presets has no curve for mode {mode_name!r}")
            curve, reason = _validate_curve(presets[mode_name])
            if curve is None:
                raise ValueError(f"invalid curve for mode {mode_name!r}: {reason}")
            curves[mode_name] = curve
        self._curves = curves
        self._thresholds = {
            key: tuple(bucket.threshold_ms for bucket in curve) for key, curve in curves.items()
        }
        # a fixed mode is not read again; a callable is read on every call
        self._mode_fn: Callable[[], object] | None = mode if callable(mode) else None
        fixed: object = None if callable(mode) else mode
        self._lag = lag
        # the monitor whose generation tells when the signals moved (None:
        # another source, read on every call), and its generation at the
        # last evaluation
        self._monitor = lag if isinstance(lag, LagMonitor) else None
        self._generation = -1
        self._deadband = deadband
        self._logger = logger or logging.getLogger("ros_mobile_bridge")
        self._warned_modes: set[str] = set()
        self._transitions = 0
        # the inputs of the last evaluation, and its outcome
        self._raw_mode: object = None
        self._recurring = math.nan
        self._sustained = math.nan
        self._mode: ThrottleMode = "auto"
        self._curve = curves["auto"]
        self._index = 0
        self._interval = 0.0
        if self._monitor is not None:
            self._generation = self._monitor.generation
        raw = fixed if self._mode_fn is None else self._mode_fn()
        self._evaluate(raw, lag.recurring_lag_ms(), lag.sustained_lag_ms(), initial=True)

    @property
    def interval(self) -> float:
        """The interval of the last :meth:`interval_s` (seconds, 0.0 = no
        cap), without evaluating again."""
        return self._interval

    def interval_s(self) -> float:
        """The minimum interval between delivered messages now, in seconds
        (0.0 = no cap). Call it for every received frame: it reads the mode
        and the lag signals and moves the bucket by the rules above."""
        mode_fn = self._mode_fn
        monitor = self._monitor
        if mode_fn is None:
            if monitor is not None:
                generation = monitor.generation
                if generation == self._generation:
                    return self._interval  # no new sample since the last call
                self._generation = generation
            raw_mode = self._raw_mode
        else:
            raw_mode = mode_fn()
        lag = self._lag
        recurring = lag.recurring_lag_ms()
        sustained = lag.sustained_lag_ms()
        if (
            recurring == self._recurring
            and sustained == self._sustained
            and raw_mode == self._raw_mode
        ):
            return self._interval
        self._evaluate(raw_mode, recurring, sustained, initial=False)
        return self._interval

    def _justified(self, mode: ThrottleMode, lag_ms: float) -> int:
        return max(bisect.bisect_right(self._thresholds[mode], lag_ms) - 1, 0)

    def _evaluate(
        self, raw_mode: object, recurring: float, sustained: float, *, initial: bool
    ) -> None:
        if raw_mode != self._raw_mode or initial:
            mode = self._effective_mode(raw_mode)
            self._raw_mode = raw_mode
        else:
            mode = self._mode
        self._recurring = recurring
        self._sustained = sustained
        floor = self._justified(mode, max(recurring, sustained))
        if mode != self._mode or initial:
            index = floor  # a new curve: no hysteresis to carry over
        else:
            index = self._index
            tighten = floor > index
            relax = sustained <= self._curve[index].threshold_ms - self._deadband
            if tighten or relax:
                index = floor
        curve = self._curves[mode]
        if not initial and (mode != self._mode or index != self._index):
            self._transitions += 1
            old = self._curve[self._index]
            new = curve[index]
            self._logger.info(
                "throttle %s: %s -> %s (%g -> %g ms between messages, mode %s); "
                "event-loop lag %.0f ms recurring, %.0f ms sustained",
                self._name or "(unnamed)",
                old.label,
                new.label,
                old.min_interval_ms,
                new.min_interval_ms,
                mode,
                recurring,
                sustained,
            )
        self._mode = mode
        self._curve = curve
        self._index = index
        self._interval = curve[index].min_interval_ms / 1000.0

    def _effective_mode(self, raw_mode: object) -> ThrottleMode:
        for name in THROTTLE_MODES:
            if raw_mode == name:
                return name
        key = repr(raw_mode)
        if key not in self._warned_modes:
            self._warned_modes.add(key)
            self._logger.warning(
                "unknown throttle mode %r (expected one of %s); using 'auto'",
                raw_mode,
                ", ".join(THROTTLE_MODES),
            )
        return "auto"

    # -- state as of the last evaluation ----------------------------------------------
    @property
    def mode(self) -> ThrottleMode:
        """The mode whose curve applies."""
        return self._mode

    @property
    def bucket(self) -> Bucket:
        """The current bucket."""
        return self._curve[self._index]

    @property
    def bucket_index(self) -> int:
        """The current bucket's position in its curve (0 = the shallowest)."""
        return self._index

    @property
    def bucket_label(self) -> str:
        """The current bucket's label (``"full rate"``, ``"10 Hz"``, ...)."""
        return self._curve[self._index].label

    @property
    def min_interval_ms(self) -> float:
        """The current cap in milliseconds (0.0 = none)."""
        return self._curve[self._index].min_interval_ms

    @property
    def at_deepest(self) -> bool:
        """Whether the current bucket is its curve's deepest (the circuit
        breaker's precondition for tripping)."""
        return self._index == len(self._curve) - 1

    @property
    def transitions(self) -> int:
        """How many times the bucket (or the mode) changed."""
        return self._transitions

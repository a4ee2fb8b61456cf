"""The adaptive throttle: the shipped curves, tighten-at-once, relax with a
deadband straight to the justified bucket, no hunting, mode switches, and the
validation of preset overrides. The lag is a hand-set fake (or a
:class:`LagMonitor` fed with explicit times): every assertion is exact."""

from __future__ import annotations

import bisect
import logging
from collections.abc import Mapping, Sequence

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge.flow._lag import LagMonitor
from ros_mobile_bridge.flow._throttle import (
    DEFAULT_PRESETS,
    THROTTLE_MODES,
    AdaptiveThrottle,
    Bucket,
    ThrottleMode,
    resolve_presets,
)

LOGGER = logging.getLogger("tests.test_throttle")


class FakeLag:
    """Both lag signals the throttle reads, set by hand."""

    def __init__(self, recurring_ms: float = 0.0, sustained_ms: float = 0.0) -> None:
        self.recurring_ms = recurring_ms
        self.sustained_ms = sustained_ms

    def set(self, recurring_ms: float, sustained_ms: float) -> None:
        self.recurring_ms = recurring_ms
        self.sustained_ms = sustained_ms

    def recurring_lag_ms(self) -> float:
        return self.recurring_ms

    def sustained_lag_ms(self) -> float:
        return self.sustained_ms


class ModeSetting:
    """The user's settings screen: a mode read on every call."""

    def __init__(self, mode: ThrottleMode = "auto") -> None:
        self.mode: ThrottleMode = mode

    def __call__(self) -> ThrottleMode:
        return self.mode


def make(
    mode: ThrottleMode = "auto",
    lag: FakeLag | None = None,
    *,
    deadband_ms: float = 10.0,
    presets: Mapping[ThrottleMode, Sequence[Bucket]] = DEFAULT_PRESETS,
) -> tuple[AdaptiveThrottle, FakeLag, ModeSetting]:
    lag = lag or FakeLag()
    setting = ModeSetting(mode)
    return AdaptiveThrottle(presets, setting, lag, deadband_ms=deadband_ms), lag, setting


def justified(mode: ThrottleMode, lag_ms: float) -> int:
    thresholds = [bucket.threshold_ms for bucket in DEFAULT_PRESETS[mode]]
    return bisect.bisect_right(thresholds, lag_ms) - 1


# -- the shipped curves ----------------------------------------------------------------------
def test_every_mode_has_a_default_curve() -> None:
    assert set(DEFAULT_PRESETS) == set(THROTTLE_MODES) == {"performance", "auto", "efficient"}


@pytest.mark.parametrize("mode", THROTTLE_MODES)
def test_default_curves_are_valid_and_cap_harder_when_deeper(mode: ThrottleMode) -> None:
    curve = DEFAULT_PRESETS[mode]
    assert all(isinstance(bucket, Bucket) for bucket in curve)
    assert curve[0].threshold_ms == 0.0
    thresholds = [b.threshold_ms for b in curve]
    intervals = [b.min_interval_ms for b in curve]
    assert thresholds == sorted(set(thresholds))
    assert intervals == sorted(set(intervals))  # strictly harder caps
    assert resolve_presets({mode: curve}, LOGGER)[mode] == curve


@pytest.mark.parametrize("mode", ["performance", "auto"])
def test_performance_and_auto_start_at_full_rate(mode: ThrottleMode) -> None:
    assert DEFAULT_PRESETS[mode][0] == Bucket(0.0, 0.0, "full rate")


def test_efficient_is_capped_from_the_start() -> None:
    assert DEFAULT_PRESETS["efficient"][0].min_interval_ms > 0


def test_performance_is_more_tolerant_than_auto_and_efficient_stricter() -> None:
    performance, auto, efficient = (DEFAULT_PRESETS[m] for m in THROTTLE_MODES)
    assert performance[1].threshold_ms > auto[1].threshold_ms > efficient[1].threshold_ms
    assert performance[-1].min_interval_ms < auto[-1].min_interval_ms
    assert efficient[-1].min_interval_ms > auto[-1].min_interval_ms


def test_default_presets_are_read_only() -> None:
    with pytest.raises(TypeError):
        DEFAULT_PRESETS["auto"] = ()  # type: ignore[index]


# -- bucket selection ----------------------------------------------------------------------
@pytest.mark.parametrize(
    ("mode", "lag_ms", "label", "interval_s"),
    [
        ("auto", 0.0, "full rate", 0.0),
        ("auto", 29.9, "full rate", 0.0),
        ("auto", 30.0, "20 Hz", 0.05),
        ("auto", 79.9, "20 Hz", 0.05),
        ("auto", 80.0, "10 Hz", 0.1),
        ("auto", 150.0, "4 Hz", 0.25),
        ("auto", 299.0, "4 Hz", 0.25),
        ("auto", 300.0, "1 Hz", 1.0),
        ("auto", 10_000.0, "1 Hz", 1.0),
        ("performance", 0.0, "full rate", 0.0),
        ("performance", 49.0, "full rate", 0.0),
        ("performance", 50.0, "30 Hz", 0.033),
        ("performance", 120.0, "15 Hz", 0.066),
        ("performance", 250.0, "10 Hz", 0.1),
        ("performance", 500.0, "4 Hz", 0.25),
        ("efficient", 0.0, "10 Hz", 0.1),
        ("efficient", 20.0, "5 Hz", 0.2),
        ("efficient", 50.0, "2 Hz", 0.5),
        ("efficient", 100.0, "1 Hz", 1.0),
        ("efficient", 200.0, "0.5 Hz", 2.0),
        ("efficient", 10_000.0, "0.5 Hz", 2.0),
    ],
)
def test_steady_lag_selects_the_justified_bucket(
    mode: ThrottleMode, lag_ms: float, label: str, interval_s: float
) -> None:
    throttle, _, _ = make(mode, FakeLag(lag_ms, lag_ms))
    assert throttle.interval_s() == pytest.approx(interval_s)
    assert throttle.bucket_label == label
    assert throttle.bucket == DEFAULT_PRESETS[mode][throttle.bucket_index]
    assert throttle.min_interval_ms == pytest.approx(interval_s * 1000)
    assert throttle.at_deepest == (throttle.bucket_index == len(DEFAULT_PRESETS[mode]) - 1)
    assert throttle.mode == mode


def test_the_state_is_valid_from_construction() -> None:
    throttle, _, _ = make("auto", FakeLag(400.0, 400.0))
    assert throttle.bucket_label == "1 Hz"
    assert throttle.at_deepest
    assert throttle.transitions == 0


# -- tighten -----------------------------------------------------------------------------
def test_tightens_at_once_straight_to_the_deepest_justified_bucket() -> None:
    throttle, lag, _ = make("auto")
    assert throttle.interval_s() == 0.0
    lag.set(recurring_ms=200.0, sustained_ms=2.0)  # one spike: the sustained lag has not moved
    assert throttle.interval_s() == 0.25
    assert throttle.bucket_label == "4 Hz"
    assert throttle.transitions == 1  # 0 -> 3 in one step


def test_a_sustained_lag_alone_also_justifies_a_deeper_bucket() -> None:
    # e.g. no frame arrived during the spike, which has left the 1 s window
    throttle, lag, _ = make("auto")
    lag.set(recurring_ms=10.0, sustained_ms=90.0)
    assert throttle.bucket_index == 0
    assert throttle.interval_s() == 0.1
    assert throttle.bucket_label == "10 Hz"


# -- relax ---------------------------------------------------------------------------------
def test_no_relax_inside_the_deadband() -> None:
    throttle, lag, _ = make("auto", FakeLag(200.0, 200.0))
    assert throttle.bucket_label == "4 Hz"  # threshold 150
    lag.set(recurring_ms=0.0, sustained_ms=149.0)
    assert throttle.interval_s() == 0.25
    lag.set(recurring_ms=0.0, sustained_ms=140.1)
    assert throttle.interval_s() == 0.25
    assert throttle.transitions == 0
    lag.set(recurring_ms=0.0, sustained_ms=140.0)  # exactly deadband_ms below: relax
    assert throttle.interval_s() == 0.1
    assert throttle.bucket_label == "10 Hz"


def test_relax_jumps_straight_to_the_bucket_the_sustained_lag_justifies() -> None:
    throttle, lag, _ = make("auto", FakeLag(1000.0, 1000.0))
    assert throttle.bucket_label == "1 Hz"
    lag.set(recurring_ms=5.0, sustained_ms=5.0)
    assert throttle.interval_s() == 0.0
    assert throttle.bucket_label == "full rate"
    assert throttle.transitions == 1  # 4 -> 0 in one step

    throttle, lag, _ = make("auto", FakeLag(1000.0, 1000.0))
    lag.set(recurring_ms=5.0, sustained_ms=85.0)
    assert throttle.interval_s() == 0.1  # 1 Hz -> 10 Hz directly
    assert throttle.transitions == 1


def test_relax_never_goes_below_what_the_recurring_lag_justifies() -> None:
    throttle, lag, _ = make("auto", FakeLag(1000.0, 1000.0))
    lag.set(recurring_ms=100.0, sustained_ms=20.0)  # calm overall, a recent bump
    assert throttle.interval_s() == 0.1  # "10 Hz" (a recurring 100 justifies it), not full rate
    lag.set(recurring_ms=100.0, sustained_ms=20.0)
    assert throttle.interval_s() == 0.1
    assert throttle.transitions == 1


def test_relaxing_is_not_a_one_way_ratchet() -> None:
    throttle, lag, _ = make("auto")
    lag.set(1000.0, 1000.0)
    throttle.interval_s()
    lag.set(0.0, 0.0)
    throttle.interval_s()
    lag.set(1000.0, 1000.0)
    assert throttle.interval_s() == 1.0
    lag.set(0.0, 0.0)
    assert throttle.interval_s() == 0.0
    assert throttle.transitions == 4


def test_zero_deadband_relaxes_as_soon_as_the_sustained_lag_is_below_the_threshold() -> None:
    throttle, lag, _ = make("auto", FakeLag(100.0, 100.0), deadband_ms=0.0)
    assert throttle.bucket_label == "10 Hz"
    lag.set(0.0, 80.0)
    assert throttle.interval_s() == 0.1  # at the threshold: stays
    lag.set(0.0, 79.9)
    assert throttle.interval_s() == 0.05


# -- no hunting --------------------------------------------------------------------------------
def test_no_hunting_when_the_lag_oscillates_inside_the_deadband() -> None:
    throttle, lag, _ = make("auto")
    for i in range(200):
        # around the 80 ms threshold, never 10 ms below it
        if i % 2:
            lag.set(recurring_ms=85.0, sustained_ms=78.0)
        else:
            lag.set(recurring_ms=75.0, sustained_ms=82.0)
        throttle.interval_s()
    assert throttle.transitions == 1  # tightened once, then held
    assert throttle.bucket_label == "10 Hz"


@pytest.mark.parametrize("fixed", [False, True], ids=["callable-mode", "fixed-mode"])
def test_no_hunting_with_the_real_monitor_and_a_lag_around_a_threshold(fixed: bool) -> None:
    monitor = LagMonitor(clock=lambda: 0.0)
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, "auto" if fixed else lambda: "auto", monitor)
    labels: list[str] = []
    for i in range(400):  # 20 s of samples every 50 ms, alternating 86 / 74 ms
        monitor.record(74.0 if i % 2 else 86.0, now=i * 0.05)
        for _ in range(3):  # a few frames between samples
            throttle.interval_s()
        labels.append(throttle.bucket_label)
    # nothing before three samples; 74 ms recurs at the third (20 Hz), 86 ms
    # at the fifth (10 Hz); then held for 20 s
    assert labels[:5] == ["full rate", "full rate", "20 Hz", "20 Hz", "10 Hz"]
    assert throttle.transitions == 2
    assert set(labels[4:]) == {"10 Hz"}


@pytest.mark.parametrize("fixed", [False, True], ids=["callable-mode", "fixed-mode"])
def test_a_burst_then_calm_relaxes_once_the_sustained_lag_falls(fixed: bool) -> None:
    monitor = LagMonitor(clock=lambda: 0.0)
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, "auto" if fixed else lambda: "auto", monitor)
    now = 0.0
    for _ in range(40):  # 2 s of 400 ms lag
        monitor.record(400.0, now=now)
        now += 0.05
    assert throttle.interval_s() == 1.0
    labels = []
    for _ in range(200):  # then 10 s calm
        monitor.record(1.0, now=now)
        now += 0.05
        throttle.interval_s()
        labels.append(throttle.bucket_label)
    # held while the p90 of the last 4 s still saw the burst, then straight to full rate
    assert labels[-1] == "full rate"
    assert throttle.transitions == 2
    first_relax = labels.index("full rate")
    assert set(labels[:first_relax]) == {"1 Hz"}


class ReadCountingMonitor(LagMonitor):
    """A real monitor that counts how often the throttle reads its signals."""

    def __init__(self) -> None:
        super().__init__(clock=lambda: 0.0)
        self.reads = 0

    def recurring_lag_ms(self) -> float:
        self.reads += 1
        return super().recurring_lag_ms()


def test_a_fixed_mode_reads_the_monitor_once_per_sample_not_per_frame() -> None:
    monitor = ReadCountingMonitor()
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, "efficient", monitor)
    assert monitor.reads == 1  # construction
    for _ in range(100):  # frames between two samples
        assert throttle.interval_s() == 0.1  # efficient's first bucket
    assert monitor.reads == 1
    for i in range(3):  # 60 ms recurring: efficient's "2 Hz"
        monitor.record(60.0, now=0.05 * (i + 1))
    for _ in range(100):
        assert throttle.interval_s() == 0.5
    assert monitor.reads == 2  # one read for the three new samples
    assert (throttle.bucket_label, throttle.transitions) == ("2 Hz", 1)
    monitor.clear()  # the signals read 0.0 again: efficient relaxes to its first bucket
    assert throttle.interval_s() == 0.1
    assert monitor.reads == 3


def test_a_callable_mode_is_read_on_every_call() -> None:
    monitor = ReadCountingMonitor()
    setting = ModeSetting("auto")
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, setting, monitor)
    assert throttle.interval_s() == 0.0
    setting.mode = "efficient"  # no new sample: the change applies to the next frame
    assert throttle.interval_s() == 0.1
    assert throttle.mode == "efficient"
    assert monitor.reads == 3


def test_an_unknown_fixed_mode_falls_back_to_auto_and_warns_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    monitor = LagMonitor(clock=lambda: 0.0)
    with caplog.at_level(logging.WARNING, logger=LOGGER.name):
        throttle = AdaptiveThrottle(
            DEFAULT_PRESETS,
            "turbo",  # type: ignore[arg-type]
            monitor,
            logger=LOGGER,
        )
        for i in range(5):
            monitor.record(1.0, now=0.05 * i)
            throttle.interval_s()
    assert throttle.mode == "auto"
    assert [r.getMessage().count("turbo") for r in caplog.records] == [1]


def test_one_stall_of_a_second_never_tightens() -> None:
    # user code blocks the loop once: the frames queued behind the stall
    # already crossed the socket, so they are delivered, not throttled
    monitor = LagMonitor(clock=lambda: 0.0)
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, lambda: "auto", monitor)
    now = 0.0
    for _ in range(100):
        now += 0.051
        monitor.record(1.0, now=now)
        throttle.interval_s()
    now += 1.0
    monitor.record(1000.0, now=now)
    for _ in range(100):
        assert throttle.interval_s() == 0.0
        now += 0.051
        monitor.record(1.0, now=now)
    assert throttle.transitions == 0


def test_a_decoder_build_right_after_start_never_tightens() -> None:
    # the monitor has just started: a 55 ms build and then calm samples
    monitor = LagMonitor(clock=lambda: 0.0)
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, lambda: "auto", monitor)
    monitor.record(55.0, now=0.05)
    assert throttle.interval_s() == 0.0
    for i in range(40):
        monitor.record(1.0, now=0.1 + i * 0.05)
        assert throttle.interval_s() == 0.0


def test_a_loop_busy_85_percent_of_the_time_tightens_within_a_second() -> None:
    # 85 ms of work, 15 ms idle, again and again: the sampler (50 ms sleep)
    # wakes about 50 ms late each time, so each sample takes about 100 ms
    monitor = LagMonitor(clock=lambda: 0.0)
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, lambda: "auto", monitor)
    now, tightened_at = 0.0, None
    for _ in range(20):
        now += 0.1
        monitor.record(50.0, now=now)
        if throttle.interval_s() > 0.0 and tightened_at is None:
            tightened_at = now
    assert tightened_at is not None
    assert tightened_at <= 1.0
    assert throttle.bucket_label == "20 Hz"


def test_every_bucket_change_is_logged_at_info_with_topic_and_lag(
    caplog: pytest.LogCaptureFixture,
) -> None:
    lag = FakeLag(0.0, 0.0)
    throttle = AdaptiveThrottle(
        DEFAULT_PRESETS, lambda: "auto", lag, logger=LOGGER, name="/camera/image_raw"
    )
    with caplog.at_level(logging.INFO, logger=LOGGER.name):
        throttle.interval_s()
        assert caplog.records == []  # no change, no line
        lag.set(160.0, 90.0)
        throttle.interval_s()
        lag.set(0.0, 0.0)
        throttle.interval_s()
    assert [r.levelno for r in caplog.records] == [logging.INFO, logging.INFO]
    tighten, relax = (r.getMessage() for r in caplog.records)
    assert "/camera/image_raw" in tighten
    assert "full rate -> 4 Hz" in tighten
    assert "0 -> 250 ms" in tighten
    assert "160 ms recurring" in tighten
    assert "90 ms sustained" in tighten
    assert "4 Hz -> full rate" in relax


# -- mode -----------------------------------------------------------------------------------
def test_a_mode_change_applies_on_the_next_call() -> None:
    throttle, lag, setting = make("auto", FakeLag(0.0, 0.0))
    assert throttle.interval_s() == 0.0
    setting.mode = "efficient"
    assert throttle.interval_s() == 0.1
    assert throttle.mode == "efficient"
    lag.set(60.0, 60.0)
    assert throttle.interval_s() == 0.5
    setting.mode = "performance"
    assert throttle.interval_s() == 0.033
    setting.mode = "auto"
    assert throttle.interval_s() == 0.05
    assert (throttle.mode, throttle.bucket_label) == ("auto", "20 Hz")


def test_a_mode_change_reevaluates_on_the_new_curve_without_hysteresis() -> None:
    throttle, lag, setting = make("auto", FakeLag(200.0, 200.0))
    lag.set(0.0, 145.0)  # inside the deadband of auto's 150: held at "4 Hz"
    assert throttle.bucket_label == "4 Hz"
    assert throttle.interval_s() == 0.25
    setting.mode = "performance"  # 145 justifies performance's "15 Hz"
    assert throttle.interval_s() == 0.066
    assert throttle.bucket_label == "15 Hz"


def test_an_unknown_mode_falls_back_to_auto_and_warns_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    throttle, _, setting = make("auto", FakeLag(40.0, 40.0))
    setting.mode = "turbo"  # type: ignore[assignment]
    with caplog.at_level(logging.WARNING):
        for _ in range(5):
            assert throttle.interval_s() == 0.05
    assert throttle.mode == "auto"
    warnings = [r for r in caplog.records if "unknown throttle mode" in r.getMessage()]
    assert len(warnings) == 1
    assert "'turbo'" in warnings[0].getMessage()


# -- constructor checks ------------------------------------------------------------------------
def test_the_constructor_rejects_a_negative_deadband() -> None:
    with pytest.raises(ValueError, match="deadband_ms"):
        make(deadband_ms=-1.0)


def test_the_constructor_rejects_missing_or_invalid_curves() -> None:
    presets = dict(DEFAULT_PRESETS)
    del presets["efficient"]
    with pytest.raises(ValueError, match="efficient"):
        make(presets=presets)
    presets = {**DEFAULT_PRESETS, "auto": (Bucket(5.0, 0.0, "x"),)}
    with pytest.raises(ValueError, match="auto"):
        make(presets=presets)


# -- preset overrides -------------------------------------------------------------------------
def test_no_overrides_give_the_defaults() -> None:
    assert resolve_presets(None, LOGGER) == dict(DEFAULT_PRESETS)
    assert resolve_presets({}, LOGGER) == dict(DEFAULT_PRESETS)


def test_a_valid_override_replaces_that_mode_only_and_accepts_plain_tuples() -> None:
    resolved = resolve_presets({"auto": [(0, 0, "full"), (100, 500, "2 Hz")]}, LOGGER)
    assert resolved["auto"] == (Bucket(0.0, 0.0, "full"), Bucket(100.0, 500.0, "2 Hz"))
    assert all(isinstance(bucket, Bucket) for bucket in resolved["auto"])
    assert isinstance(resolved["auto"][1].threshold_ms, float)
    assert resolved["performance"] == DEFAULT_PRESETS["performance"]
    assert resolved["efficient"] == DEFAULT_PRESETS["efficient"]
    throttle = AdaptiveThrottle(resolved, lambda: "auto", FakeLag(120.0, 120.0))
    assert throttle.bucket_label == "2 Hz"


INVALID_CURVES: list[tuple[str, object, str]] = [
    ("empty", [], "empty"),
    ("first threshold not 0", [(5, 0, "a"), (10, 100, "b")], "first threshold_ms must be 0"),
    ("equal thresholds", [(0, 0, "a"), (50, 100, "b"), (50, 200, "c")], "increase strictly"),
    ("decreasing thresholds", [(0, 0, "a"), (50, 100, "b"), (40, 200, "c")], "increase strictly"),
    ("negative interval", [(0, -1, "a")], "min_interval_ms must be >= 0"),
    ("decreasing interval", [(0, 0, "a"), (50, 200, "b"), (90, 100, "c")], "must not decrease"),
    ("label not str", [(0, 0, "a"), (50, 100, 7)], "label must be a str"),
    ("two-field bucket", [(0, 0)], "must be (threshold_ms, min_interval_ms, label)"),
    ("string threshold", [("0", 0, "a")], "threshold_ms must be a finite number"),
    ("bool interval", [(0, True, "a")], "min_interval_ms must be a finite number"),
    ("nan threshold", [(0, 0, "a"), (float("nan"), 1, "b")], "threshold_ms must be a finite"),
    ("infinite interval", [(0, 0, "a"), (10, float("inf"), "b")], "min_interval_ms must be a"),
    ("not a sequence", {"0": 0}, "must be a sequence of buckets"),
    ("a string", "fast", "must be a sequence of buckets"),
]


@pytest.mark.parametrize(
    ("curve", "reason"),
    [(curve, reason) for _, curve, reason in INVALID_CURVES],
    ids=[name for name, _, _ in INVALID_CURVES],
)
def test_an_invalid_override_warns_and_falls_back_for_that_mode_only(
    curve: object, reason: str, caplog: pytest.LogCaptureFixture
) -> None:
    good = ((0.0, 0.0, "full"), (10.0, 20.0, "50 Hz"))
    with caplog.at_level(logging.WARNING, logger=LOGGER.name):
        resolved = resolve_presets({"efficient": curve, "performance": good}, LOGGER)  # type: ignore[dict-item]
    assert resolved["efficient"] == DEFAULT_PRESETS["efficient"]
    assert resolved["performance"] == tuple(Bucket(*b) for b in good)  # still applied
    assert resolved["auto"] == DEFAULT_PRESETS["auto"]
    [record] = [r for r in caplog.records if r.name == LOGGER.name]
    assert record.levelno == logging.WARNING
    message = record.getMessage()
    assert "'efficient'" in message
    assert reason in message


def test_an_unknown_mode_name_in_overrides_raises_value_error() -> None:
    with pytest.raises(ValueError, match="'eficient'"):
        resolve_presets({"eficient": DEFAULT_PRESETS["efficient"]}, LOGGER)


def test_overrides_that_are_not_a_mapping_raise_type_error() -> None:
    with pytest.raises(TypeError, match="mapping"):
        resolve_presets([("auto", DEFAULT_PRESETS["auto"])], LOGGER)  # type: ignore[arg-type]


# -- properties -------------------------------------------------------------------------------
lags = st.floats(min_value=0.0, max_value=2000.0, allow_nan=False)
steps = st.lists(st.tuples(lags, lags, st.sampled_from(THROTTLE_MODES)), min_size=1, max_size=60)


@settings(max_examples=examples(300), deadline=None)
@given(steps=steps, deadband=st.sampled_from([0.0, 5.0, 10.0, 40.0]))
def test_the_bucket_is_always_between_what_the_lag_and_the_deadband_justify(
    steps: list[tuple[float, float, ThrottleMode]], deadband: float
) -> None:
    lag = FakeLag()
    setting = ModeSetting(steps[0][2])
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, setting, lag, deadband_ms=deadband)
    previous_mode = throttle.mode
    for recurring_ms, sustained_ms, mode in steps:
        lag.set(recurring_ms, sustained_ms)
        setting.mode = mode
        interval = throttle.interval_s()
        index = throttle.bucket_index
        assert throttle.mode == mode
        # never shallower than the recurring lag (nor the sustained lag) justifies
        assert index >= justified(mode, recurring_ms)
        assert index >= justified(mode, sustained_ms)
        # deeper only by the deadband's hysteresis
        assert index <= justified(mode, max(recurring_ms, sustained_ms + deadband))
        if mode != previous_mode:
            assert index == justified(mode, max(recurring_ms, sustained_ms))
        assert interval == DEFAULT_PRESETS[mode][index].min_interval_ms / 1000.0
        # the same inputs again never move the bucket (no hunting on a steady lag)
        transitions = throttle.transitions
        assert throttle.interval_s() == interval
        assert throttle.transitions == transitions
        previous_mode = mode


@settings(max_examples=examples(200), deadline=None)
@given(
    history=st.lists(st.tuples(lags, lags), min_size=1, max_size=30),
    calm=st.floats(min_value=0.0, max_value=2000.0, allow_nan=False),
)
def test_a_steady_lag_settles_on_its_justified_bucket_unless_held_by_the_deadband(
    history: list[tuple[float, float]], calm: float
) -> None:
    lag = FakeLag()
    throttle = AdaptiveThrottle(DEFAULT_PRESETS, lambda: "auto", lag)
    for recurring_ms, sustained_ms in history:
        lag.set(recurring_ms, sustained_ms)
        throttle.interval_s()
    held = throttle.bucket_index
    lag.set(calm, calm)
    throttle.interval_s()
    target = justified("auto", calm)
    threshold = DEFAULT_PRESETS["auto"][held].threshold_ms
    if target >= held or calm <= threshold - 10.0:
        assert throttle.bucket_index == target
    else:
        assert throttle.bucket_index == held

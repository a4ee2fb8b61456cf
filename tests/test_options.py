"""``ClientOptions``: safe defaults, and every bad value rejected with
``ValueError`` / ``TypeError`` when the options are built."""

from __future__ import annotations

import dataclasses
import logging
import math
import ssl

import pytest

from ros_mobile_bridge import BreakerPolicy, ClientOptions, ReconnectPolicy

# field -> may it be zero?
FLOAT_FIELDS = {
    "connect_timeout": False,
    "discovery_grace": True,
    "keepalive_interval": True,
    "read_coalesce": True,
    "keepalive_timeout": False,
    "service_timeout": False,
    "teardown_timeout": False,
    "advertise_settle": True,
    "discovery_interval": False,
    "latency_probe_interval": True,
    "fragment_timeout": False,
    "type_description_timeout": False,
}
# field -> smallest valid value
INT_FIELDS = {
    "max_frame_size": 1024,
    "subscription_buffer": 1,
    "max_json_depth": 2,
    "max_channels": 1,
    "max_services": 1,
    "max_schema_size": 64,
    "max_schema_fields": 1,
    "max_pending_requests": 1,
    "zenoh_backlog": 1,
    "zenoh_backlog_bytes": 1024,
    "type_description_hold": 1,
}


def test_defaults() -> None:
    opts = ClientOptions()
    assert opts.connect_timeout == 10.0
    assert opts.discovery_grace == 0.2
    assert opts.max_frame_size == 64 * 1024 * 1024
    assert opts.keepalive_interval == 10.0
    assert opts.keepalive_timeout == 10.0
    assert opts.service_timeout == 10.0
    assert opts.teardown_timeout == 2.0
    assert opts.advertise_settle == 0.15
    assert opts.stop_topics == ()
    assert opts.zero_twist_on_exit is True
    assert opts.subscription_buffer == 1024
    assert opts.ssl_context is None
    assert isinstance(opts.logger, logging.Logger)
    assert opts.logger.name == "ros_mobile_bridge"
    assert opts.on_latency is None
    assert opts.reconnect == ReconnectPolicy()
    assert opts.breaker == BreakerPolicy()
    assert opts.throttle_mode == "auto"
    assert opts.preset_overrides is None
    assert opts.discovery_interval == 2.0
    assert opts.latency_probe_interval == 5.0
    assert opts.fragment_timeout == 10.0
    assert opts.headers == ()
    assert opts.rosbridge_auth is None
    assert opts.http_client is None


def test_limit_defaults() -> None:
    """The inbound limits: safe, documented defaults (the docs' limits table)."""
    opts = ClientOptions()
    assert opts.max_json_depth == 100
    assert opts.max_channels == 10_000
    assert opts.max_services == 10_000
    assert opts.max_schema_size == 256 * 1024
    assert opts.max_schema_fields == 500
    assert opts.max_pending_requests == 256
    assert opts.type_description_timeout == 3.0
    assert opts.type_description_hold == 256


def test_type_description_timeout_must_be_finite() -> None:
    with pytest.raises(ValueError, match="finite"):
        ClientOptions(type_description_timeout=math.inf)


def test_every_field_is_covered_here() -> None:
    names = {f.name for f in dataclasses.fields(ClientOptions)}
    others = {
        "stop_topics",
        "zero_twist_on_exit",
        "ssl_context",
        "logger",
        "on_latency",
        "reconnect",
        "breaker",
        "throttle_mode",
        "preset_overrides",
        "domain_id",
        "zenoh_shared_memory",
        # tests/test_connection_options.py and tests/test_httpx_transport.py
        "headers",
        "rosbridge_auth",
        "http_client",
        # tests/test_interfaces.py
        "interface_paths",
        "ament_prefix_path",
        # tests/test_zenoh_secure.py
        "zenoh_security",
        "zenoh_config",
        # below, and tests/test_error_contract.py
        "unknown_topic_warning",
    }
    assert names == set(FLOAT_FIELDS) | set(INT_FIELDS) | others


def test_unknown_topic_warning_is_seconds_or_none() -> None:
    assert ClientOptions().unknown_topic_warning == 3.0
    assert ClientOptions(unknown_topic_warning=None).unknown_topic_warning is None
    assert ClientOptions(unknown_topic_warning=0.5).unknown_topic_warning == 0.5
    for bad in (0, -1.0, math.nan):
        with pytest.raises(ValueError, match="unknown_topic_warning"):
            ClientOptions(unknown_topic_warning=bad)
    with pytest.raises(TypeError, match="unknown_topic_warning"):
        ClientOptions(unknown_topic_warning="3")  # type: ignore[arg-type]


def test_options_are_frozen() -> None:
    opts = ClientOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.connect_timeout = 1.0  # type: ignore[misc]


def test_valid_values_are_kept() -> None:
    def on_latency(ms: float) -> None:
        pass

    logger = logging.getLogger("tests.test_options")
    context = ssl.create_default_context()
    opts = ClientOptions(
        connect_timeout=3,
        discovery_grace=0,
        keepalive_interval=0,
        keepalive_timeout=0.5,
        service_timeout=math.inf,
        teardown_timeout=0.25,
        advertise_settle=0.0,
        max_frame_size=1024,
        subscription_buffer=1,
        stop_topics=["/cmd_vel", "/robot/cmd_vel"],
        zero_twist_on_exit=False,
        ssl_context=context,
        logger=logger,
        on_latency=on_latency,
    )
    assert opts.connect_timeout == 3
    assert opts.discovery_grace == 0
    assert opts.service_timeout == math.inf
    assert opts.stop_topics == ("/cmd_vel", "/robot/cmd_vel")  # stored as a tuple
    assert (opts.ssl_context, opts.logger, opts.on_latency) == (context, logger, on_latency)
    assert dataclasses.replace(opts, connect_timeout=1.0).stop_topics == opts.stop_topics


def test_stop_topics_accepts_any_sequence_or_iterable() -> None:
    assert ClientOptions(stop_topics=("/a",)).stop_topics == ("/a",)
    assert ClientOptions(stop_topics=iter(["/a", "/b"])).stop_topics == ("/a", "/b")  # type: ignore[arg-type]


# -- numeric fields ---------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(FLOAT_FIELDS))
@pytest.mark.parametrize("value", [-1, -0.001, -math.inf])
def test_float_fields_reject_negative(name: str, value: float) -> None:
    with pytest.raises(ValueError, match=name):
        ClientOptions(**{name: value})


@pytest.mark.parametrize("name", sorted(FLOAT_FIELDS))
def test_float_fields_zero(name: str) -> None:
    if FLOAT_FIELDS[name]:
        assert getattr(ClientOptions(**{name: 0}), name) == 0
    else:
        with pytest.raises(ValueError, match=name):
            ClientOptions(**{name: 0})
        with pytest.raises(ValueError, match=name):
            ClientOptions(**{name: 0.0})


@pytest.mark.parametrize("name", sorted(FLOAT_FIELDS))
@pytest.mark.parametrize("value", [True, False, "10", b"1", None, [1.0], 1j])
def test_float_fields_reject_non_numbers(name: str, value: object) -> None:
    with pytest.raises(TypeError, match=name):
        ClientOptions(**{name: value})


@pytest.mark.parametrize("name", sorted(FLOAT_FIELDS))
def test_float_fields_reject_nan(name: str) -> None:
    with pytest.raises(ValueError, match=name):
        ClientOptions(**{name: math.nan})


@pytest.mark.parametrize("name", sorted(INT_FIELDS))
def test_int_fields_minimum(name: str) -> None:
    minimum = INT_FIELDS[name]
    assert getattr(ClientOptions(**{name: minimum}), name) == minimum
    for bad in (minimum - 1, 0, -1):
        with pytest.raises(ValueError, match=name):
            ClientOptions(**{name: bad})


@pytest.mark.parametrize("name", sorted(INT_FIELDS))
@pytest.mark.parametrize("value", [True, False, 2048.0, "2048", None, math.nan])
def test_int_fields_reject_non_ints(name: str, value: object) -> None:
    with pytest.raises(TypeError, match=name):
        ClientOptions(**{name: value})


# -- stop_topics ------------------------------------------------------------------------------
def test_stop_topics_as_a_str_is_a_type_error() -> None:
    with pytest.raises(TypeError, match="stop_topics"):
        ClientOptions(stop_topics="/cmd_vel")  # type: ignore[arg-type]


@pytest.mark.parametrize("topics", [["cmd_vel"], ["/cmd_vel", "robot/cmd_vel"], [""], ["~/cmd"]])
def test_relative_stop_topics_are_rejected(topics: list[str]) -> None:
    with pytest.raises(ValueError, match="stop_topics"):
        ClientOptions(stop_topics=topics)


@pytest.mark.parametrize("topics", [[None], [1], [b"/cmd_vel"], 5])
def test_stop_topics_entries_must_be_strings(topics: object) -> None:
    with pytest.raises((TypeError, ValueError)):
        ClientOptions(stop_topics=topics)  # type: ignore[arg-type]


# -- logger and callbacks ----------------------------------------------------------------------
@pytest.mark.parametrize(
    "logger",
    [None, "ros_mobile_bridge", print, logging.LoggerAdapter(logging.getLogger("x"), {})],
)
def test_logger_must_be_a_logging_logger(logger: object) -> None:
    with pytest.raises(TypeError, match="logger"):
        ClientOptions(logger=logger)  # type: ignore[arg-type]


def test_a_logger_subclass_is_accepted() -> None:
    class MyLogger(logging.Logger):
        pass

    logger = MyLogger("mine")
    assert ClientOptions(logger=logger).logger is logger
    assert ClientOptions(logger=logging.getLogger()).logger is logging.getLogger()


@pytest.mark.parametrize("callback", ["print", 1, object()])
def test_on_latency_must_be_callable(callback: object) -> None:
    with pytest.raises(TypeError, match="on_latency"):
        ClientOptions(on_latency=callback)  # type: ignore[arg-type]


# -- ReconnectPolicy ---------------------------------------------------------------------
def test_reconnect_policy_backoff_grows_to_the_cap_with_jitter_bounds() -> None:
    policy = ReconnectPolicy(initial_delay=0.5, max_delay=4.0, multiplier=2.0, jitter=0.2)
    mid = [policy.delay(n, lambda: 0.5) for n in range(1, 7)]  # 0.5: no jitter
    assert mid == [0.5, 1.0, 2.0, 4.0, 4.0, 4.0]
    assert policy.delay(1, lambda: 0.0) == pytest.approx(0.4)
    assert policy.delay(1, lambda: 0.999999) == pytest.approx(0.6, abs=1e-5)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"initial_delay": -1},
        {"max_delay": math.nan},
        {"multiplier": 0.5},
        {"jitter": 1.0},
        {"jitter": -0.1},
        {"initial_delay": 5, "max_delay": 1},
        {"max_attempts": 0},
        {"max_attempts": True},
        {"max_attempts": 1.5},
    ],
)
def test_reconnect_policy_rejects_bad_values(kwargs: dict[str, object]) -> None:
    with pytest.raises((ValueError, TypeError)):
        ReconnectPolicy(**kwargs)  # type: ignore[arg-type]


def test_reconnect_must_be_a_policy_or_none() -> None:
    assert ClientOptions(reconnect=None).reconnect is None
    with pytest.raises(TypeError, match="reconnect"):
        ClientOptions(reconnect=True)  # type: ignore[arg-type]


# -- throttle and breaker options ---------------------------------------------------------
def test_throttle_mode_must_be_a_mode_or_a_callable() -> None:
    assert ClientOptions(throttle_mode="efficient").throttle_mode == "efficient"
    assert callable(ClientOptions(throttle_mode=lambda: "performance").throttle_mode)
    with pytest.raises(ValueError, match="throttle_mode"):
        ClientOptions(throttle_mode="turbo")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "kwargs",
    [{"cooldowns_s": ()}, {"saturation_ms": 0}, {"dwell_s": -1}, {"probe_s": math.nan}],
)
def test_breaker_policy_rejects_bad_values(kwargs: dict[str, object]) -> None:
    with pytest.raises((ValueError, TypeError)):
        BreakerPolicy(**kwargs)  # type: ignore[arg-type]


def test_breaker_must_be_a_policy_or_none() -> None:
    assert ClientOptions(breaker=None).breaker is None
    with pytest.raises(TypeError, match="breaker"):
        ClientOptions(breaker=object())  # type: ignore[arg-type]

"""The parts of the sans-IO Foxglove engine; the public face is
:mod:`ros_mobile_bridge.wire.foxglove`, which re-exports what callers use."""

__all__: list[str] = []

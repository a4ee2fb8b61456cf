"""The parts of the sans-IO rosbridge v2 engine; the public face is
:mod:`ros_mobile_bridge.wire.rosbridge`, which re-exports what callers use."""

__all__: list[str] = []

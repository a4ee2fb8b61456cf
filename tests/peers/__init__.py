"""Real peers for the tests and benchmarks: servers this project did not write,
started and stopped by the test itself on loopback."""

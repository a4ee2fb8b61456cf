"""The committed message classes (src/ros_mobile_bridge/interfaces/<package>/)
are what scripts/gen_message_classes.py writes from the bundled interfaces
today: regenerated in memory and compared file by file, as
tests/test_interfaces.py holds the bundle to its generator."""

from __future__ import annotations

from _message_classes import generator
from ros_mobile_bridge.codec._bundled import bundled_packages


def test_the_committed_classes_are_current() -> None:
    gen = generator()
    wanted = gen.generate()
    problems = list(gen.differences(wanted, gen.existing()))
    assert problems == [], "run: python scripts/gen_message_classes.py\n" + "\n".join(problems)


def test_the_generator_is_deterministic_and_covers_every_bundled_package() -> None:
    gen = generator()
    first = gen.generate()
    assert gen.generate() == first
    assert {path.split("/")[0] for path in first} == set(bundled_packages())
    for path, text in first.items():
        assert text.startswith(gen.HEADER), path


def test_one_module_per_interface_named_as_rosidl_names_it() -> None:
    gen = generator()
    files = gen.generate()
    assert "geometry_msgs/msg.py" not in files
    for path in (
        "geometry_msgs/msg/__init__.py",
        "geometry_msgs/msg/_twist_with_covariance.py",
        "sensor_msgs/msg/_point_cloud2.py",
        "trajectory_msgs/msg/_multi_dof_joint_trajectory.py",
        "example_interfaces/srv/_add_two_ints.py",
        "example_interfaces/action/_fibonacci.py",
    ):
        assert path in files, path
    for path, text in files.items():
        if not path.endswith("__init__.py"):
            assert text.count("\nclass ") == 1, path  # one top-level class
        assert text.count("\n") <= 900, path  # the house's limit on a file

"""What the demo robot offers beside its topics and services: its robot
description and the mesh it names, as assets (Foxglove's ``assets``:
``client.fetch_asset``), and its connection graph (``connectionGraph``:
``client.nodes()``, ``client.topic_endpoints()``)."""

from __future__ import annotations

from collections.abc import Iterable
from importlib import resources
from typing import Final

import foxglove

__all__ = ["ASSETS", "NODE", "connection_graph", "serve_asset"]

NODE: Final = "/rmb_demo_robot"
"""The one node of the demo robot's graph: it publishes every topic,
subscribes to the velocity topics and provides every service."""

ASSETS: Final[dict[str, str]] = {
    "package://rmb_demo/urdf/rmb_demo.urdf": "rmb_demo.urdf",
    "package://rmb_demo/meshes/base.stl": "base.stl",
}
"""The URIs the robot serves, and their files in this package's ``assets/``."""


def serve_asset(uri: str) -> bytes:
    """The Foxglove server's asset handler: the file of ``uri``;
    ``FileNotFoundError`` (the client's ``AssetError`` says it) for a URI the
    robot does not serve. Only the files listed in :data:`ASSETS` are read."""
    name = ASSETS.get(uri)
    if name is None:
        raise FileNotFoundError(f"the demo robot serves no {uri} (it serves {', '.join(ASSETS)})")
    return (resources.files(__package__) / "assets" / name).read_bytes()


def connection_graph(
    published: Iterable[str], subscribed: Iterable[str], services: Iterable[str]
) -> foxglove.ConnectionGraph:
    """The robot's graph: :data:`NODE` publishes ``published``, subscribes
    to ``subscribed`` and provides ``services``."""
    graph = foxglove.ConnectionGraph()
    for topic in published:
        graph.set_published_topic(topic, [NODE])
    for topic in subscribed:
        graph.set_subscribed_topic(topic, [NODE])
    for service in services:
        graph.set_advertised_service(service, [NODE])
    return graph

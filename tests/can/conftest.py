"""Fixtures of the CAN-edge tests: configs (our DBC, the foreign one) and live rigs."""

from __future__ import annotations

import pytest
from canhelpers import DATA, ROOT, VirtualRig

from gyrostand.config import load_config


@pytest.fixture(scope="session")
def demo_cfg():
    return load_config(ROOT / "configs" / "demo.yaml")


@pytest.fixture(scope="session")
def triad_cfg():
    return load_config(ROOT / "configs" / "three-gyros.yaml")


@pytest.fixture(scope="session")
def foreign_cfg():
    return load_config(DATA / "foreign.yaml")


@pytest.fixture
def rig_factory():
    """Make VirtualRig(listeners); every rig is closed after the test."""
    rigs = []

    def make(listeners):
        rig = VirtualRig(listeners)
        rigs.append(rig)
        return rig

    yield make
    for r in rigs:
        r.close()

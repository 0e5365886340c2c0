"""The installed package is the abi3 wheel: one build for every CPython >= 3.9."""

import sys
from importlib import metadata

import handeye


def test_the_installed_wheel_is_abi3_for_cpython_3_9_and_later():
    wheel = metadata.distribution("handeye").read_text("WHEEL")
    tags = [line.split(":", 1)[1].strip() for line in wheel.splitlines() if line.startswith("Tag:")]
    assert tags and all(tag.startswith("cp39-abi3-") for tag in tags), tags
    if sys.platform != "win32":
        assert handeye._handeye.__file__.endswith(".abi3.so"), handeye._handeye.__file__
    assert metadata.version("handeye") == handeye.__version__

"""The Design record: .npz round trip and clear errors on malformed files."""

import numpy as np
import pytest

from dbtool.design import Design, DesignFileError
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.tasks import get_task


def _design():
    task = get_task("crawling")
    robot = reference_robot(task, "star")
    return Design("crawling", robot, task.controller(), surface=np.random.rand(64, 3),
                  metrics={"crawling": 0.01}, meta={"seed": 3})


def test_round_trip(tmp_path):
    d = _design()
    path = d.save(tmp_path / "d.npz")
    e = Design.load(path)
    assert e.task == d.task and e.metrics == d.metrics and e.meta == d.meta
    for k, v in d.arrays().items():
        np.testing.assert_array_equal(e.arrays()[k], v)
    assert not list(tmp_path.glob("*.tmp*")) and len(list(tmp_path.iterdir())) == 1


@pytest.mark.parametrize("content", [b"", b"not a zip", b"PK\x03\x04garbage"])
def test_malformed_files(tmp_path, content):
    path = tmp_path / "bad.npz"
    path.write_bytes(content)
    with pytest.raises(DesignFileError):
        Design.load(path)


def test_missing_and_inconsistent(tmp_path):
    with pytest.raises(DesignFileError, match="not found"):
        Design.load(tmp_path / "nope.npz")
    d = _design()
    arrays = d.arrays()
    arrays["controller"] = np.zeros((100, 3))
    header = '{"format": "dbtool.design/1", "task": "crawling"}'
    np.savez(tmp_path / "x.npz", header=np.array(header), **arrays)
    with pytest.raises(DesignFileError, match="controller"):
        Design.load(tmp_path / "x.npz")
    arrays = d.arrays()
    arrays.pop("occupancy")
    np.savez(tmp_path / "y.npz", header=np.array("{}"), **arrays)
    with pytest.raises(DesignFileError, match="lacks occupancy"):
        Design.load(tmp_path / "y.npz")

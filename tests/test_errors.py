"""User errors become one line; bugs keep their traceback (docs/architecture.md, cli)."""

import pytest
import typer

from dbtool import errors
from dbtool.cli.common import guarded
from dbtool.compare.executors import ExecutorError
from dbtool.compare.run import CompareError
from dbtool.design import DesignFileError
from dbtool.pointcloud import CloudFileError
from dbtool.realgap.log import LogError
from dbtool.robotize.robotizer import RobotizeError
from dbtool.sim.rollout import MetricError
from dbtool.sim.stepper import SimulationError
from dbtool.sim.tasks.base import DetachedError


def _exit_code(exc: BaseException) -> int:
    with pytest.raises(typer.Exit) as info, guarded():
        raise exc
    return info.value.exit_code


def test_a_user_error_is_one_line_and_exit_2(capsys):
    assert _exit_code(errors.InputError("steps must be at least 1, got 0")) == 2
    assert capsys.readouterr().err.strip() == "error: steps must be at least 1, got 0"


def test_a_bug_keeps_its_traceback():
    for bug in (ValueError("operands could not be broadcast"), KeyError("x"),
                TypeError("bad"), OSError("no filename: not a user's path")):
        with pytest.raises(type(bug)), guarded():
            raise bug


def test_a_missing_named_file_is_a_user_error(tmp_path, capsys):
    with pytest.raises(typer.Exit), guarded():
        open(tmp_path / "absent.npz")  # noqa: SIM115
    assert "absent.npz" in capsys.readouterr().err


@pytest.mark.parametrize("cls", [ExecutorError, CompareError, DesignFileError, CloudFileError,
                                 LogError, RobotizeError, MetricError, SimulationError,
                                 DetachedError])
def test_every_domain_error_is_a_dbtool_error(cls):
    assert issubclass(cls, errors.DbtoolError)


def test_the_string_settings_of_the_method_are_checked():
    """A typo in a mode is an error naming the choices, not a silent fall into one branch."""
    from dbtool.codesign.config import CodesignConfig, EmbeddingConfig, preset

    for field, bad in (("target", "x_0"), ("gradient", "scored "), ("handover", "last")):
        with pytest.raises(errors.InputError, match=f"{field} must be one of"):
            CodesignConfig(**{field: bad})
    with pytest.raises(errors.InputError, match="space must be one of mixture, captions, free"):
        EmbeddingConfig(buffer_size=60, space="mix")
    emb, cod = preset("quick", "gripping")  # every preset is valid
    assert emb.space == "mixture" and cod.target == "x0"

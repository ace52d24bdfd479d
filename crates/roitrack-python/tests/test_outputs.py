"""Python's writers (Camera.to_yaml, Target.to_csv) go through the command line's output discipline
(docs/cameras.md#outputs): a file appears whole or not at all, a failed write leaves the previous file as it was and
no temporary, a symbolic link stays a link, and the temporaries a killed process left are removed by the next write of
the same output."""

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import roitrack

GRID = np.array([[x, y, 0.0] for y in (-0.03, -0.01, 0.01, 0.03) for x in (-0.03, -0.01, 0.01, 0.03)])


def temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".") and p.name.endswith((".tmp", ".old")))


def test_a_failed_write_leaves_the_previous_file_and_no_temporary(tmp_path: Path) -> None:
    camera = roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0)
    path = tmp_path / "camera.yaml"
    path.write_text("previous\n")
    # A folder where the file would go, and a folder that is missing: refused, naming the path.
    (tmp_path / "folder.yaml").mkdir()
    with pytest.raises(roitrack.RoitrackError, match="folder.yaml: is a directory"):
        camera.to_yaml(tmp_path / "folder.yaml")
    with pytest.raises(roitrack.RoitrackError, match="missing. does not exist"):
        camera.to_yaml(tmp_path / "missing" / "camera.yaml")
    assert path.read_text() == "previous\n"
    assert temporaries(tmp_path) == []
    assert not (tmp_path / "missing").exists()
    camera.to_yaml(path)
    assert roitrack.Camera.from_file(path).fx == 500.0
    # Through a symbolic link: the file it leads to is replaced, the link stays a link.
    link = tmp_path / "link.csv"
    link.symlink_to("target.csv")
    roitrack.Target(GRID).to_csv(link)
    assert link.is_symlink() and roitrack.Target.from_csv(tmp_path / "target.csv").points_m.shape == (16, 3)
    assert temporaries(tmp_path) == []


def test_temporaries_of_a_killed_process_go_with_the_next_write(tmp_path: Path) -> None:
    ended = subprocess.Popen(["true"])
    ended.wait()
    stale = tmp_path / f".target.csv.{ended.pid}.aB3xYz.tmp"
    stale.write_text("half a file")
    # This process's parent is alive: a run writing the same output now keeps its temporary; another output's too.
    alive = tmp_path / f".target.csv.{os.getppid()}.aB3xYz.tmp"
    alive.write_text("being written")
    other = tmp_path / f".camera.yaml.{ended.pid}.aB3xYz.tmp"
    other.write_text("another output")
    roitrack.Target(GRID).to_csv(tmp_path / "target.csv")
    assert not stale.exists()
    assert alive.exists() and other.exists()

"""No file we load runs code: a crafted checkpoint or demonstrations file never creates
the marker its pickled payload would create, through any load path."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from lvws_ros.errors import ModelError
from lvws_ros.learning.checkpoint import load_checkpoint, read_checkpoint
from lvws_ros.learning.demonstrations import load_demos
from lvws_ros.learning.training import TrainConfig, train
from lvws_ros.registry import make_policy


class Payload:
    """Unpickling this calls os.system, which creates the marker file."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (os.system, (f"touch {self.marker}",))


@pytest.fixture
def crafted(tmp_path: Path) -> tuple[Path, Path, Path, Path]:
    marker = tmp_path / "payload-ran"
    pt = tmp_path / "crafted.pt"
    torch.save({"format": "lvws-model/1", "config": {}, "state_dict": {}, "meta": Payload(marker)}, pt)
    npz = tmp_path / "crafted.npz"
    np.savez(npz, header=np.array([Payload(marker)], dtype=object))  # an object array is pickled
    raw = tmp_path / "crafted-pickle.npz"
    raw.write_bytes(pickle.dumps(Payload(marker)))
    # each payload really runs when loaded the unsafe way (so the test can fail)
    for unsafe in (lambda: torch.load(pt, weights_only=False), lambda: np.load(npz, allow_pickle=True)["header"],
                   lambda: pickle.loads(raw.read_bytes())):
        unsafe()
        assert marker.exists()
        marker.unlink()
    return marker, pt, npz, raw


def test_checkpoint_load_paths_refuse_the_payload(crafted):
    marker, pt, _, _ = crafted
    for load in (read_checkpoint, load_checkpoint):
        with pytest.raises(ModelError, match=r"crafted\.pt"):
            load(pt)
    for name in ("lvws", "dbgm", "lvws_rollout", "lvws_beam"):
        with pytest.raises(ModelError):
            make_policy(name, model_path=str(pt))
    with pytest.raises(ModelError):
        train([], TrainConfig(epochs=1), resume=pt, progress=False, log=lambda _t: None)
    assert not marker.exists()


def test_demonstration_files_refuse_the_payload(crafted):
    marker, _, npz, raw = crafted
    for path in (npz, raw):
        with pytest.raises(ModelError, match=path.name):
            load_demos(path)
    assert not marker.exists()


def test_the_cli_refuses_a_crafted_model_with_exit_2(crafted, tmp_path):
    from conftest import REPO

    marker, pt, _, _ = crafted
    res = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "solve", str(REPO / "config" / "example_instance.json"),
                          "--policy", "lvws", "--model", str(pt)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 2 and "crafted.pt" in res.stderr and "Traceback" not in res.stderr, res.stderr
    assert not marker.exists()


def test_demonstrations_of_different_sizes_round_trip(tmp_path):
    from lvws_ros.core.datasets import DATASETS, dataset_instance
    from lvws_ros.learning.demonstrations import expert_demos, save_demos

    demos = [*expert_demos(dataset_instance(DATASETS["II"], 3, 0), time_limit=5, workers=2),
             *expert_demos(dataset_instance(DATASETS["II"], 5, 0), time_limit=5, workers=2)]
    assert len({d.expert.shape for d in demos}) > 1
    save_demos(demos, tmp_path / "d.npz", {"k": 1})
    back, meta = load_demos(tmp_path / "d.npz")
    assert meta == {"k": 1} and len(back) == len(demos)
    for a, b in zip(demos, back, strict=True):
        for x, y in ((a.features.robots, b.features.robots), (a.features.tasks, b.features.tasks),
                     (a.features.edges, b.features.edges), (a.features.rows, b.features.rows),
                     (a.features.cols, b.features.cols), (a.features.pairs, b.features.pairs),
                     (a.features.task_ids, b.features.task_ids), (a.expert, b.expert), (a.mask, b.mask)):
            assert x.dtype == y.dtype and np.array_equal(x, y)
    save_demos([], tmp_path / "e.npz")
    assert load_demos(tmp_path / "e.npz") == ([], {})

"""Model checkpoints (``lvws-model/2``): the shipped models, loading and saving.

A checkpoint is a dict of tensors and plain data (format, network config, state dict,
meta with the training record; optionally the optimizer state and epoch of a training
run). It is loaded with ``torch.load(weights_only=True)``, so a file never runs code.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from lvws_ros.errors import ModelError
from lvws_ros.learning.gatn import GATN, GATNConfig

__all__ = ["CHECKPOINT_FORMAT", "DEFAULT_MODELS", "MODEL_DIR", "load_checkpoint", "read_checkpoint",
           "save_checkpoint"]

MODEL_DIR = Path(__file__).resolve().parent / "models"
DEFAULT_MODELS = {"lvws": MODEL_DIR / "lvws.pt", "dbgm": MODEL_DIR / "dbgm.pt"}
CHECKPOINT_FORMAT = "lvws-model/2"  # /1: the first network (raw capability vectors, dense masks)


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    """The checkpoint's data (ModelError if missing or not ``lvws-model/2``)."""
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"{p}: model checkpoint not found")
    try:
        data = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many kinds on a file that is not a checkpoint
        raise ModelError(f"{p}: not a loadable checkpoint ({type(exc).__name__}: {exc})") from None
    if not isinstance(data, dict) or data.get("format") != CHECKPOINT_FORMAT:
        raise ModelError(f"{p}: not an {CHECKPOINT_FORMAT} checkpoint")
    return data


def load_checkpoint(path: str | Path) -> tuple[GATN, dict[str, Any]]:
    """A model (in eval mode) and its metadata (training config, seeds, data)."""
    data = read_checkpoint(path)
    try:
        model = GATN(GATNConfig.from_dict(data["config"]))
        model.load_state_dict(data["state_dict"])
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise ModelError(f"{path}: checkpoint does not match the network ({type(exc).__name__}: {exc})") from None
    model.eval()
    return model, data.get("meta", {})


def save_checkpoint(path: str | Path, model: GATN, meta: dict[str, Any],
                    optimizer: torch.optim.Optimizer | None = None, epoch: int = 0) -> None:
    """Write atomically (a temporary file, then a rename): never a half-written checkpoint."""
    data: dict[str, Any] = {
        "format": CHECKPOINT_FORMAT,
        "config": model.cfg.to_dict(),
        "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        "meta": meta,
        "epoch": epoch,
    }
    if optimizer is not None:
        data["optimizer"] = optimizer.state_dict()
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_suffix(p.suffix + ".tmp")
    torch.save(data, tmp)
    tmp.replace(p)

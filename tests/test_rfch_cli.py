"""``twin train``, ``twin detect`` and ``twin roc`` end to end on tiny generated images."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from twin.cli import main
from twin.rfch import RFCH
from twin.rfch.synthetic import cloudy_background, paste, striped_object

TRAIN_X = ["train", "--name", "x", "--images", "{data}/train"]
SMALL = ["--clusters", "12", "--patch-size", "24", "--stride", "12"]


def write_rgb(path: Path, image: np.ndarray) -> None:
    assert cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))


def write_mask(path: Path, mask: np.ndarray) -> None:
    assert cv2.imwrite(str(path), mask.astype(np.uint8) * 255)


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """train/ + train_masks/ (two views), frames/ + frame_masks/ (object at known columns)."""
    root = tmp_path_factory.mktemp("rfch_cli")
    rng = np.random.default_rng(0)
    obj, mask = striped_object(30)
    for sub in ("train", "train_masks", "frames", "frame_masks", "cutouts"):
        (root / sub).mkdir()
    for index, angle in enumerate((0.0, 60.0)):
        frame, frame_mask = paste(cloudy_background(rng, 72, 96), obj, mask, (48, 36), 1.0, angle)
        write_rgb(root / "train" / f"view{index}.png", frame)
        write_mask(root / "train_masks" / f"view{index}.png", frame_mask)
        rgba = np.dstack([frame, frame_mask.astype(np.uint8) * 255])
        assert cv2.imwrite(str(root / "cutouts" / f"view{index}.png"), rgba[..., [2, 1, 0, 3]])
    for index in range(4):
        x = 20 + 18 * index
        frame, frame_mask = paste(cloudy_background(rng, 72, 96), obj, mask, (x, 40), 0.9, 30.0)
        write_rgb(root / "frames" / f"f{index}.jpg", frame)
        write_mask(root / "frame_masks" / f"f{index}.png", frame_mask)
    return root


def test_train_detect_roc_end_to_end(data: Path, tmp_path: Path, capsys) -> None:
    model_path = tmp_path / "rings.npz"
    args = ["train", "--name", "rings", "--images", str(data / "train")]
    args += ["--masks", str(data / "train_masks"), "--out", str(model_path), *SMALL]
    assert main(args) == 0
    model = RFCH.load(model_path)
    assert model.name == "rings" and model.summary["views"] == 2
    assert model.params.patch_size == 24 and model.params.n_clusters == 12

    out_png = tmp_path / "detect.png"
    image = data / "frames" / "f2.jpg"
    assert main(["detect", "--model", str(model_path), str(image), "--out", str(out_png)]) == 0
    printed = capsys.readouterr().out
    assert "rings: best column" in printed
    drawn = cv2.imread(str(out_png))
    assert drawn is not None and drawn.shape[0] > drawn.shape[1]  # frame above the profile

    roc_png = tmp_path / "roc.png"
    args = ["roc", "--model", str(model_path), "--images", str(data / "frames")]
    args += ["--masks", str(data / "frame_masks"), "--out", str(roc_png)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "AUC" in printed and "P_fp" in printed
    assert cv2.imread(str(roc_png)) is not None
    with open(roc_png.with_suffix(".csv")) as handle:
        rows = list(csv.DictReader(handle))
    p_fp = np.array([float(r["p_fp"]) for r in rows])
    p_fn = np.array([float(r["p_fn"]) for r in rows])
    assert p_fp[0] == 1.0 and p_fn[0] == 0.0  # lowest threshold detects everything
    assert p_fp[-1] == 0.0 and p_fn[-1] == 1.0  # above the maximum nothing is detected
    assert np.all(np.diff(p_fp) <= 0) and np.all(np.diff(p_fn) >= 0)


def test_detect_with_two_models_draws_both(data: Path, tmp_path: Path, capsys) -> None:
    paths = []
    for name, extra in (("a", []), ("b", ["--seed", "3", "--views", "per_view"])):
        paths.append(tmp_path / f"{name}.npz")
        args = ["train", "--name", name, "--images", str(data / "train")]
        args += ["--masks", str(data / "train_masks"), "--out", str(paths[-1]), *SMALL, *extra]
        assert main(args) == 0
    out_png = tmp_path / "two.png"
    args = ["detect", "--model", str(paths[0]), "--model", str(paths[1])]
    assert main([*args, str(data / "frames" / "f0.jpg"), "--out", str(out_png)]) == 0
    printed = capsys.readouterr().out
    assert "a: best column" in printed and "b: best column" in printed
    assert "2 codebooks" in printed and "twin train-shared" in printed  # seeds differ: 2 of them


def test_train_from_alpha_cutouts(data: Path, tmp_path: Path) -> None:
    with_alpha = tmp_path / "alpha.npz"
    args = ["train", "--name", "r", "--images", str(data / "cutouts"), "--out", str(with_alpha)]
    assert main([*args, *SMALL]) == 0
    with_masks = tmp_path / "masks.npz"
    args = ["train", "--name", "r", "--images", str(data / "train")]
    args += ["--masks", str(data / "train_masks"), "--out", str(with_masks), *SMALL]
    assert main(args) == 0
    np.testing.assert_array_equal(RFCH.load(with_alpha).centres, RFCH.load(with_masks).centres)


@pytest.mark.parametrize(
    ("command", "message"),
    [
        (["detect", "--model", "{tmp}/missing.npz", "{data}/frames/f0.jpg"], "no such file"),
        (["detect", "--model", "{tmp}/junk.npz", "{data}/frames/f0.jpg"], "not a readable"),
        (["detect", "--model", "{tmp}/m.npz", "{tmp}/nothing.png"], "no such image file"),
        (["train", "--name", "x", "--images", "{tmp}/nowhere", "--out", "{tmp}/x.npz"], "no such"),
        (["train", "--name", "x", "--images", "{data}/train", "--out", "{tmp}/x.npz"], "alpha"),
        (
            [*TRAIN_X, "--masks", "{data}/frames", "--out", "{tmp}/x.npz"],
            "no mask for view0.png",
        ),
        (
            [*TRAIN_X, "--masks", "{data}/train_masks", "--out", "{tmp}/x.npz", "--clusters", "1"],
            "n_clusters",
        ),
    ],
)
def test_bad_paths_and_values_are_one_line_errors(
    data: Path, tmp_path: Path, capsys, command, message
) -> None:
    (tmp_path / "junk.npz").write_bytes(b"junk")
    frame, mask = paste(
        cloudy_background(np.random.default_rng(1), 72, 96), *striped_object(30), (40, 30)
    )
    RFCH.train("m", [frame], [mask], n_clusters=8).save(tmp_path / "m.npz")
    args = [part.format(tmp=tmp_path, data=data) for part in command]
    if args[0] == "detect":
        args += ["--out", str(tmp_path / "o.png")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_train_shared_and_reuse_a_codebook(data: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "models"
    args = ["train-shared", "--object", f"rings={data / 'train'}:{data / 'train_masks'}"]
    args += ["--object", f"cut={data / 'cutouts'}", "--out-dir", str(out), *SMALL]
    assert main(args) == 0
    rings, cut = RFCH.load(out / "rings.npz"), RFCH.load(out / "cut.npz")
    assert rings.codebook_key == cut.codebook_key
    assert rings.summary["codebook"]["objects"] == ["rings", "cut"]

    late = tmp_path / "late.npz"
    args = ["train", "--name", "late", "--images", str(data / "cutouts")]
    assert main([*args, "--codebook", str(out / "rings.npz"), "--out", str(late)]) == 0
    assert RFCH.load(late).codebook_key == rings.codebook_key
    assert main([*args, "--codebook", str(out / "rings.npz"), "--out", str(late), "--alpha", "2"])
    assert "only views, view_similarity, max_view_models" in capsys.readouterr().err
    image = str(data / "frames" / "f0.jpg")
    args = ["detect", "--model", str(out / "rings.npz"), "--model", str(late), image]
    assert main([*args, "--out", str(tmp_path / "shared.png")]) == 0
    assert "codebooks" not in capsys.readouterr().out  # one codebook: nothing to advise

    bad = ["train-shared", "--object", "nameless", "--out-dir", str(out)]
    assert main(bad) == 2
    assert "NAME=IMAGES" in capsys.readouterr().err


def test_train_clustered_views_on_a_shared_codebook(data: Path, tmp_path: Path, capsys) -> None:
    """View parameters from the command line, also for an object added to a codebook."""
    out = tmp_path / "models"
    args = ["train-shared", "--object", f"rings={data / 'train'}:{data / 'train_masks'}"]
    assert main([*args, "--out-dir", str(out), "--views", "clustered", *SMALL]) == 0
    rings = RFCH.load(out / "rings.npz")
    assert rings.params.views == "clustered" and len(rings.summary["view_models"]) == 2
    late = tmp_path / "late.npz"
    args = ["train", "--name", "late", "--images", str(data / "cutouts"), "--out", str(late)]
    args += ["--codebook", str(out / "rings.npz"), "--views", "clustered"]
    assert main([*args, "--view-similarity", "0.9", "--max-view-models", "1"]) == 0
    late_model = RFCH.load(late)
    assert late_model.codebook_key == rings.codebook_key and len(late_model.histograms) == 1
    assert main([*args, "--view-similarity", "2"]) != 0
    err = capsys.readouterr().err
    assert "view_similarity must be in [0, 1]" in err and err.count("\n") == 1

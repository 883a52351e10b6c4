"""``twin train``, ``twin detect`` and ``twin roc``: the RFCH detector from the command line.

File conventions:
- Images: ``.png .jpg .jpeg .bmp .tif .tiff`` files, 8-bit colour, read in name order.
- Masks (``--masks DIR``): for image ``NAME.ext`` the mask is ``DIR/NAME.png``, 8-bit, any
  nonzero pixel is the object (a colour mask counts a pixel nonzero in any channel). For
  ``twin roc`` an all-zero mask is allowed and means "the object is not in this frame".
- Without ``--masks``, ``twin train`` takes the object from each image's alpha channel
  (a cut-out PNG: alpha > 0 is the object).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from twin.commands._args import comma_list
from twin.core.errors import InputError
from twin.rfch.calibration import DEFAULT_BINS
from twin.rfch.params import VIEW_MODES, RFCHParams

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def register(subparsers: argparse._SubParsersAction) -> None:
    train = subparsers.add_parser(
        "train",
        help="train an RFCH model of one object from images with masks",
        description="Train an RFCH model (codebook + cooccurrence histogram) of one object. "
        + __doc__.split("File conventions:")[1].replace("\n-", "\n *"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    train.add_argument("--name", required=True, help="object name stored in the model")
    train.add_argument("--images", required=True, type=Path, help="directory of training views")
    train.add_argument("--masks", type=Path, help="directory of masks NAME.png (nonzero = object)")
    train.add_argument("--out", required=True, type=Path, help="model file to write (.npz)")
    train.add_argument(
        "--codebook",
        type=Path,
        help="reuse this model's codebook and parameters (then only --views may be given), so "
        "that a Detector labels and counts pairs once for both objects",
    )
    _add_parameters(train)
    train.set_defaults(handler=_train)

    shared = subparsers.add_parser(
        "train-shared",
        help="train several objects on one shared codebook (faster detection of many objects)",
        description="Train several objects on ONE k-means codebook and write DIR/NAME.npz for "
        "each. A Detector with these models labels each frame and counts its pixel pairs once; "
        "every further object costs only histogram intersections. "
        + __doc__.split("File conventions:")[1].replace("\n-", "\n *"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    shared.add_argument(
        "--object",
        required=True,
        action="append",
        metavar="NAME=IMAGES[:MASKS]",
        help="an object: its name, its image directory and optionally its mask directory",
    )
    shared.add_argument("--out-dir", required=True, type=Path, help="directory for the models")
    _add_parameters(shared)
    shared.set_defaults(handler=_train_shared)

    detect = subparsers.add_parser(
        "detect",
        help="score every patch of an image and draw the heat-map and column profile",
        description="Score every patch of IMAGE for each model; write a PNG with the score "
        "heat-map over the frame and the per-column maximum below, one pair of panels per model.",
    )
    detect.add_argument("--model", required=True, action="append", type=Path, help="model file")
    detect.add_argument("image", type=Path, help="image file (8-bit colour)")
    detect.add_argument("--out", required=True, type=Path, help="PNG to write")
    detect.set_defaults(handler=_detect)

    roc = subparsers.add_parser(
        "roc",
        help="ROC curve of a model on labelled frames, and the threshold to give the grid",
        description="Score labelled frames and write the per-column ROC (PNG and CSV). A column "
        "is positive when one of its patches has at least --min-cover of its area on the mask, "
        "negative when none of its pixels is, and left out otherwise; its score is the maximum "
        "over its patches. Prints AUC, the chosen threshold and its (P_fp, P_fn), and the "
        "score calibration: columns on and off the object per score bin and the log-likelihood "
        "ratio each bin gives the 'calibrated' fusion rule (--store keeps it in the model).",
    )
    roc.add_argument("--model", required=True, type=Path, help="model file")
    roc.add_argument("--images", required=True, type=Path, help="directory of frames")
    roc.add_argument("--masks", required=True, type=Path, help="directory of masks NAME.png")
    roc.add_argument("--out", required=True, type=Path, help="ROC plot to write (.png)")
    roc.add_argument("--csv", type=Path, help="ROC table to write (default: --out with .csv)")
    roc.add_argument("--min-cover", type=float, default=0.25, help="positive patch cover (0.25)")
    roc.add_argument(
        "--max-fp",
        type=float,
        help="choose the least P_fn with P_fp at most this (default: least P_fp + P_fn)",
    )
    roc.add_argument(
        "--bins",
        type=int,
        default=DEFAULT_BINS,
        help=f"equal score bins over [0, 1] for the calibration ({DEFAULT_BINS})",
    )
    roc.add_argument(
        "--store",
        action="store_true",
        help="write the measured calibration into the --model file (replacing any it holds)",
    )
    roc.set_defaults(handler=_roc)


def _add_parameters(parser: argparse.ArgumentParser) -> None:
    """The RFCH parameters; left out, each takes its default (shown in brackets)."""
    defaults = RFCHParams()
    options: list[tuple[str, Any, str]] = [
        ("--clusters", int, f"k-means centres N ({defaults.n_clusters})"),
        ("--alpha", float, f"rejection factor α ({defaults.alpha})"),
        ("--d-max", float, f"pair distance, px ({defaults.d_max})"),
        (
            "--sigmas",
            comma_list(float, "Gaussian scales in px"),
            f"Gaussian scales, px ({','.join(f'{v:g}' for v in defaults.sigmas)})",
        ),
        ("--colour-weight", float, f"weight of r, g ({defaults.colour_weight})"),
        ("--sample-step", int, f"label every n-th px ({defaults.sample_step})"),
        ("--patch-size", int, f"patch side, px ({defaults.patch_size})"),
        ("--stride", int, f"patch stride, px ({defaults.stride})"),
        ("--seed", int, f"k-means seed ({defaults.seed})"),
    ]
    for flag, kind, text in options:
        parser.add_argument(flag, type=kind, help=text)
    parser.add_argument(
        "--views",
        choices=VIEW_MODES,
        help="one histogram over all views, one per view, or similar views clustered into a "
        f"few models ({defaults.views})",
    )
    parser.add_argument(
        "--view-similarity",
        type=float,
        help="clustered: merge views that match each other on average at least this "
        f"({defaults.view_similarity})",
    )
    parser.add_argument(
        "--max-view-models",
        type=int,
        help=f"clustered: at most this many models per object ({defaults.max_view_models})",
    )


_PARAMETER_NAMES = {
    "clusters": "n_clusters",
    "alpha": "alpha",
    "d_max": "d_max",
    "sigmas": "sigmas",
    "colour_weight": "colour_weight",
    "sample_step": "sample_step",
    "patch_size": "patch_size",
    "stride": "stride",
    "seed": "seed",
    "views": "views",
    "view_similarity": "view_similarity",
    "max_view_models": "max_view_models",
}


def _parameters(args: argparse.Namespace) -> dict[str, Any]:
    """The RFCH parameters given on the command line, by their ``RFCHParams`` names."""
    return {
        field: getattr(args, option)
        for option, field in _PARAMETER_NAMES.items()
        if getattr(args, option) is not None
    }


# ---------------------------------------------------------------------------- file reading


def list_images(directory: Path) -> list[Path]:
    if not directory.is_dir():
        raise InputError(f"{directory}: no such directory; give a directory of images")
    files = sorted(p for p in directory.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise InputError(f"{directory}: holds no image ({', '.join(IMAGE_SUFFIXES)})")
    return files


def read_image(path: Path, keep_alpha: bool = False) -> Any:
    """H×W×3 uint8 RGB (H×W×4 RGBA with ``keep_alpha`` if the file has alpha)."""
    import cv2
    import numpy as np

    if not path.is_file():
        raise InputError(f"{path}: no such image file; check the path")
    data = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if data is None:
        raise InputError(f"{path}: not a readable image; give a PNG or JPEG file")
    if data.dtype != np.uint8:
        raise InputError(f"{path}: is {data.dtype} per channel; RFCH needs an 8-bit image")
    if data.ndim == 2 or data.shape[2] == 1:
        raise InputError(f"{path}: is a grey image; RFCH needs colour (normalized r, g)")
    if data.shape[2] == 4:
        rgba = cv2.cvtColor(data, cv2.COLOR_BGRA2RGBA)
        return rgba if keep_alpha else np.ascontiguousarray(rgba[..., :3])
    if keep_alpha:
        raise InputError(
            f"{path}: has no alpha channel; give --masks DIR or cut-out PNGs with alpha"
        )
    return cv2.cvtColor(data, cv2.COLOR_BGR2RGB)


def read_mask(image_path: Path, masks: Path, shape: tuple[int, ...]) -> Any:
    """Bool mask ``masks/<stem>.png`` of ``image_path`` (nonzero = object)."""
    import cv2

    path = masks / f"{image_path.stem}.png"
    if not path.is_file():
        raise InputError(
            f"{path}: no mask for {image_path.name}; masks are NAME.png, nonzero = object"
        )
    data = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if data is None:
        raise InputError(f"{path}: not a readable PNG mask")
    mask = data != 0 if data.ndim == 2 else (data != 0).any(axis=2)
    if mask.shape != tuple(shape[:2]):
        raise InputError(
            f"{path}: mask is {mask.shape[0]}×{mask.shape[1]} but {image_path.name} is "
            f"{shape[0]}×{shape[1]}; masks must match their images"
        )
    return mask


# ---------------------------------------------------------------------------- handlers


def _read_views(images_dir: Path, masks_dir: Path | None) -> tuple[list[Any], list[Any]]:
    """Training images and bool masks: from ``masks_dir``, or from each image's alpha channel."""
    images, masks = [], []
    for path in list_images(images_dir):
        if masks_dir is None:
            rgba = read_image(path, keep_alpha=True)
            images.append(rgba[..., :3].copy())
            masks.append(rgba[..., 3] > 0)
        else:
            image = read_image(path)
            images.append(image)
            masks.append(read_mask(path, masks_dir, image.shape))
    return images, masks


def _describe(path: Path, model: Any) -> str:
    summary = model.summary
    return (
        f"{path}: {model.name!r} from {summary['views']} view(s), "
        f"{summary['object_pixels']} object px, {model.n_clusters} clusters"
    )


def _train(args: argparse.Namespace) -> int:
    from twin.app.outputs import check_output_file
    from twin.rfch import RFCH

    check_output_file(args.out, "--out")
    images, masks = _read_views(args.images, args.masks)
    codebook = RFCH.load(args.codebook) if args.codebook else None
    model = RFCH.train(args.name, images, masks, codebook=codebook, **_parameters(args))
    model.save(args.out)
    print(_describe(args.out, model))
    return 0


def _train_shared(args: argparse.Namespace) -> int:
    from twin.app.outputs import check_output_folder
    from twin.rfch import RFCH

    check_output_folder(args.out_dir, "--out-dir", lambda _: True, "")  # models go beside others
    objects = {}
    for text in args.object:
        name, _, dirs = text.partition("=")
        images_dir, _, masks_dir = dirs.partition(":")
        if not name or not images_dir:
            raise InputError(f"--object {text!r}: expected NAME=IMAGES or NAME=IMAGES:MASKS")
        if name in objects:
            raise InputError(f"--object {name!r} is given twice; object names must differ")
        objects[name] = _read_views(Path(images_dir), Path(masks_dir) if masks_dir else None)
    models = RFCH.train_shared(objects, **_parameters(args))
    for model in models:
        path = args.out_dir / f"{model.name}.npz"
        model.save(path)
        print(_describe(path, model))
    return 0


def _detect(args: argparse.Namespace) -> int:
    from twin.app.outputs import check_output_file
    from twin.rfch import RFCH, Detector

    check_output_file(args.out, "--out")
    detector = Detector([RFCH.load(path) for path in args.model])
    image = read_image(args.image)
    scores = detector.scores(image)
    spans = detector.column_spans(image.shape[1])
    for name, layer in zip(detector.names, scores, strict=True):
        profile = layer.max(axis=0)
        best = int(profile.argmax())
        print(
            f"{name}: best column {best} (px {spans[best, 0]:.0f}–{spans[best, 1]:.0f}), "
            f"score {profile[best]:.3f}"
        )
    if detector.n_codebooks > 1:
        print(
            f"note: these {len(detector.models)} models use {detector.n_codebooks} codebooks, so "
            "each frame is labelled once per codebook; 'twin train-shared' (or 'twin train "
            "--codebook') puts them on one and each extra object then costs a few %"
        )
    _draw_detection(args.out, image, detector, scores)
    print(f"wrote {args.out}")
    return 0


def _draw_detection(out: Path, image: Any, detector: Any, scores: Any) -> None:
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from twin.core.store import write_atomic

    boxes = detector.patch_boxes(image.shape)
    spans = detector.column_spans(image.shape[1])
    n = len(scores)
    fig, axes = plt.subplots(
        2 * n, 1, figsize=(6, 6.2 * n), gridspec_kw={"height_ratios": [3, 1] * n}, squeeze=False
    )
    for index, (name, layer) in enumerate(zip(detector.names, scores, strict=True)):
        # Each pixel shows the best patch that covers it (patches overlap when stride < size).
        heat = np.zeros(image.shape[:2], dtype=np.float32)
        for (x0, y0, x1, y1), value in zip(boxes.reshape(-1, 4), layer.ravel(), strict=True):
            np.maximum(heat[y0:y1, x0:x1], value, out=heat[y0:y1, x0:x1])
        top, bottom = axes[2 * index, 0], axes[2 * index + 1, 0]
        top.imshow(image)
        shown = top.imshow(heat, cmap="inferno", alpha=0.55, vmin=0.0, vmax=1.0)
        top.set_title(f"{name}: RFCH match per patch")
        top.set_axis_off()
        fig.colorbar(shown, ax=top, fraction=0.03, pad=0.01)
        profile = layer.max(axis=0)
        centres = spans.mean(axis=1)
        bottom.bar(centres, profile, width=detector.grid.stride * 0.9, color="tab:orange")
        bottom.set_xlim(0, image.shape[1])
        bottom.set_ylim(0, 1)
        bottom.set_xlabel("image column (px)")
        bottom.set_ylabel("max over rows")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    write_atomic(out, lambda handle: handle.write(buffer.getvalue()))


def _roc(args: argparse.Namespace) -> int:
    import io
    from dataclasses import replace

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from twin.app.outputs import check_output_file
    from twin.core.store import write_atomic, write_text_atomic
    from twin.rfch import RFCH
    from twin.rfch.calibration import ScoreCalibration
    from twin.rfch.roc import column_truth, roc_curve

    if args.max_fp is not None and not 0.0 <= args.max_fp <= 1.0:
        raise InputError(f"--max-fp must be in [0, 1], got {args.max_fp}")
    if args.bins < 2:
        raise InputError(f"--bins must be at least 2, got {args.bins}")
    check_output_file(args.out, "--out")
    if args.csv is not None:
        check_output_file(args.csv, "--csv")
    model = RFCH.load(args.model)
    all_scores, all_truth = [], []
    for path in list_images(args.images):
        image = read_image(path)
        mask = read_mask(path, args.masks, image.shape)
        all_scores.append(model.scores(image).max(axis=0))
        all_truth.append(column_truth(mask, model.params.grid, args.min_cover))
    scores, truth = np.concatenate(all_scores), np.concatenate(all_truth)
    roc = roc_curve(scores, truth)
    calibration = ScoreCalibration.from_columns(scores, truth, args.bins, min_cover=args.min_cover)
    threshold, p_fp, p_fn = roc.choose(args.max_fp)
    csv_path = args.csv or args.out.with_suffix(".csv")
    rows = ["threshold,p_fp,p_fn"] + [
        f"{t:.6g},{fp:.6f},{fn:.6f}"
        for t, fp, fn in zip(roc.thresholds, roc.p_fp, roc.p_fn, strict=True)
    ]
    write_text_atomic(csv_path, "\n".join(rows) + "\n")

    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.plot(roc.p_fp, 1.0 - roc.p_fn, drawstyle="steps-post", label=f"AUC {roc.auc:.3f}")
    ax.plot([p_fp], [1.0 - p_fn], "o", label=f"threshold {threshold:.3f}")
    ax.plot([0, 1], [0, 1], ":", color="grey")
    ax.set_xlabel("P_fp (false positive rate)")
    ax.set_ylabel("1 − P_fn (true positive rate)")
    ax.set_title(f"{model.name}: {roc.positives} positive, {roc.negatives} negative columns")
    ax.legend(loc="lower right")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    write_atomic(args.out, lambda handle: handle.write(buffer.getvalue()))
    print(
        f"AUC {roc.auc:.3f} over {roc.positives} positive and {roc.negatives} negative columns; "
        f"threshold {threshold:.4f} gives P_fp {p_fp:.3f}, P_fn {p_fn:.3f}"
    )
    print(f"calibration: {calibration.describe()}")
    print(calibration.table_text())
    print(f"wrote {args.out} and {csv_path}")
    if args.store:
        replace(model, calibration=calibration).save(args.model)
        print(f"stored the calibration in {args.model}")
    return 0

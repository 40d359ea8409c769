"""`check_folder`: read a scene folder as training and evaluation would, and list every problem.

The first thing to run on a downloaded dataset (`gsbench data check PATH`). It goes through the
loader's own readers (layout detection, the registered layout's camera reader and its label checks,
the synthetic-scene reader) part by part, decodes every image whole and reads every label file
eagerly, where a run reads them lazily. A problem is recorded as one line naming the file, and the
check goes on with the next file or part, so one run lists every bad file instead of the first.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gsbench.errors import InputError

from . import ovs
from .guard import CameraProblems
from .imageio import image_size, list_images, read_gray, read_rgb
from .layout_registry import AUTO, Layout, get_layout
from .loader import SYNTHETIC_META, _attach_synthetic, _base_scene, detect_layout, load_scene


@dataclass
class FolderReport:
    """What `check_folder` found: the facts as text lines and the problems, one line each."""

    path: str
    layout: str | None = None
    facts: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def lines(self) -> list[str]:
        out = [f"scene     {self.path}"] + self.facts
        if self.problems:
            out.append(f"problems  {len(self.problems)}")
            out += [f"  problem: {p}" for p in self.problems]
        else:
            out.append("problems  none")
        return out


def _record(rep: FolderReport, e: InputError) -> None:
    """One problem line, or one per bad view when the cameras failed their check."""
    rep.problems.extend(e.problems if isinstance(e, CameraProblems) else [str(e)])


def _sizes_text(sizes) -> str:
    return ", ".join(sorted({f"{w}x{h}" for w, h in sizes})) or "-"


def _decode_all(paths: list, sizes: list, rep: FolderReport) -> None:
    """Decode every image whole, as training does (a truncated PNG or JPEG passes a header check
    and fails here), each at the size its camera says (`sizes[i]` None: no size check)."""
    ok = 0
    for p, size in zip(paths, sizes):
        try:
            read_rgb(Path(p), size)
            ok += 1
        except InputError as e:
            if str(e) not in rep.problems:     # an image the header check named already
                rep.problems.append(str(e))
    rep.facts.append(f"decoded   {ok} of {len(paths)} images whole")


def _views(root: Path, layout: str, rep: FolderReport):
    """(scene or None, image names, image sizes): the cameras, else the bare image list."""
    try:
        scene = _base_scene(root, layout)
    except InputError as e:
        _record(rep, e)
        scene = None
    if scene is not None:
        names = [Path(p).name for p in scene.image_paths]
        sizes = [(c.width, c.height) for c in scene.cameras]
        m = scene.meta
        rep.facts.append(f"views     {len(names)} images, {_sizes_text(sizes)}")
        rep.facts.append(f"poses     {len(scene.cameras)} from {m.get('poses_from', '?')}")
        extra = m.get("images_without_pose")
        if extra:
            rep.problems.append(f"{root / 'images'}: {extra} images have no pose in {m.get('poses_from')} "
                                "(label indices count the posed images only)")
        pts = f"{len(scene.points)} sparse points" if scene.has_points else \
            "none (training starts from random points; `gsbench points` triangulates them)"
        rep.facts.append(f"points    {pts}")
        rep.facts.append(f"split     {len(scene.train_ids)} train / {len(scene.test_ids)} test "
                         f"({m.get('split', '?')})")
        _decode_all(scene.image_paths, sizes, rep)
        return scene, names, sizes
    try:
        paths = list_images(root / "images")
    except InputError as e:
        rep.problems.append(str(e))
        return None, [], []
    names, sizes = [p.name for p in paths], []
    for p in paths:   # an unreadable image keeps its place: label indices count every image
        try:
            sizes.append(image_size(p))
        except InputError as e:
            if str(e) not in rep.problems:     # the camera reader may have named this image already
                rep.problems.append(str(e))
            sizes.append(None)
    rep.facts.append(f"views     {len(names)} images, {_sizes_text(x for x in sizes if x)}")
    rep.facts.append("poses     none usable (see the problems)")
    _decode_all([p for p, size in zip(paths, sizes) if size], [size for size in sizes if size], rep)
    return None, names, sizes


def check_3dovs_labels(root: Path, names: list[str], sizes: list, rep: FolderReport) -> None:
    seg_dir = root / "segmentations"
    try:
        classes = ovs.read_classes(seg_dir)
    except InputError as e:
        rep.problems.append(str(e))
        return
    rep.facts.append(f"classes   {len(classes)}: {', '.join(classes)}")
    files = ovs.scan_segmentations(seg_dir, classes, len(names), rep.problems)
    folders = {int(d.name): d for d in seg_dir.iterdir() if d.is_dir() and d.name.isdigit()}
    rep.facts.append(f"3D-OVS    {len(files)} labelled frames (segmentations/<index>/<class>.png)")
    for i in sorted(files):
        got = []
        for c in classes:
            f = files[i].get(c)
            if f is None:
                rep.problems.append(f"{folders[i] / (c + '.png')}: class mask missing (class {c!r} of classes.txt; "
                                    "the 3D-OVS reference stops on it, gsbench scores the class as empty)")
                continue
            try:
                m = read_gray(f, sizes[i])   # sizes[i] None (unreadable image): no size check
            except InputError as e:
                rep.problems.append(str(e))
                continue
            bad = ~np.isin(m, (0, 255))
            if bad.any():
                rep.problems.append(f"{f}: {int(bad.sum())} pixels are neither 0 nor 255 (only 255 is foreground)")
            got.append((m.shape[1], m.shape[0]))
        rep.facts.append(f"  view {i:3d} {names[i]}: {len(got)}/{len(classes)} class masks {_sizes_text(got)}")


def check_lerf_labels(root: Path, names: list[str], sizes: list, rep: FolderReport) -> None:
    ldir = ovs.find_label_dir(root)
    if ldir is None:
        rep.problems.append(f"{root / 'label'}: no LERF-OVS label files (label/{root.name}/frame_XXXXX.json)")
        return
    files = ovs.label_files(ldir, len(names), rep.problems)
    queries: set[str] = set()
    lines = []
    for i in sorted(files):
        f = files[i]
        try:
            info, objs = ovs.read_lerf_label(f, sizes[i], rep.problems)
            w, h = ovs.label_size(f, info, names[i], *sizes[i]) if sizes[i] else (info.get("width"), info.get("height"))
        except InputError as e:
            rep.problems.append(str(e))
            continue
        named = info.get("name")
        if isinstance(named, str) and named and Path(named).stem != f.stem:
            rep.problems.append(f"{f}: info.name is {named!r} but the file name makes it view {i} ({names[i]}); "
                                "LangSplat's evaluation indexes frames by info.name")
        queries.update(o.category for o in objs)
        lines.append(f"  view {i:3d} {names[i]}: {f.name} {w}x{h}, {len(objs)} objects")
    rep.facts.append(f"LERF-OVS  {len(lines)} labelled frames ({ldir})")
    rep.facts += lines
    rep.facts.append(f"queries   {len(queries)}: {', '.join(sorted(queries))}")


def _check_synthetic(root: Path, scene, rep: FolderReport) -> None:
    """gsbench_scene.json and the GT files it names (depth, instance maps) of every view."""
    if scene is None:   # a consequence of a problem already listed, not one of its own
        rep.facts.append(f"synthetic {SYNTHETIC_META} present, not checked (the cameras did not load)")
        return
    try:
        _attach_synthetic(scene, root)
    except InputError as e:
        rep.problems.append(str(e))
        return
    for i in range(len(scene.cameras)):
        for read in (scene.gt_depth, scene.gt_instances):
            try:
                read(i)
            except InputError as e:
                rep.problems.append(str(e))
    rep.facts.append(f"synthetic {SYNTHETIC_META}: GT depth and instance maps of {len(scene.cameras)} views, "
                     f"split {len(scene.train_ids)} train / {len(scene.test_ids)} test")


def check_kaolin(root: Path, rep: FolderReport) -> None:
    """The kaolin layout's own check: its reader, then every view's class map."""
    try:
        s = load_scene(root, "kaolin")
    except InputError as e:
        _record(rep, e)
        return
    sizes = [(c.width, c.height) for c in s.cameras]
    rep.facts.append(f"views     {len(sizes)} images, {_sizes_text(sizes)}")
    rep.facts.append(f"poses     {len(sizes)} from {s.meta.get('poses_from', '?')}")
    rep.facts.append("points    none (training starts from random points)")
    rep.facts.append(f"classes   {len(s.class_names)}: {', '.join(s.class_names)} "
                     f"(every view labelled: views/<i>_semantic.png)")
    for i in range(len(s.cameras)):
        try:
            s.gt_classes(i)
        except InputError as e:
            rep.problems.append(str(e))


def _check_read(root: Path, layout: Layout, rep: FolderReport) -> None:
    """A layout with a reader only (a plugin's): read the folder whole and decode every image."""
    try:
        scene = load_scene(root, layout.name)
    except InputError as e:
        _record(rep, e)
        return
    sizes = [(c.width, c.height) for c in scene.cameras]
    rep.facts.append(f"views     {len(sizes)} images, {_sizes_text(sizes)}")
    _decode_all(scene.image_paths, sizes, rep)


def check_folder(path: str | Path, layout: str = "auto") -> FolderReport:
    """Every fact and problem of a scene folder (see the module docstring); never raises on bad data."""
    root = Path(path)
    rep = FolderReport(str(root))
    if not root.is_dir():
        rep.problems.append(f"{root}: scene folder not found")
        return rep
    asked = None if layout == AUTO else get_layout(layout)
    try:
        lay = asked or get_layout(detect_layout(root))
    except InputError as e:
        rep.problems.append(str(e))
        return rep
    rep.layout = lay.name
    rep.facts.append(f"layout    {lay.name}")
    if lay.check is not None:
        lay.check(root, rep)
        return rep
    if lay.cameras is None:
        _check_read(root, lay, rep)
        return rep
    scene, names, sizes = _views(root, lay.name, rep)
    for check in lay.label_checks if names else ():
        check(root, names, sizes, rep)
    if lay.extras and (root / SYNTHETIC_META).is_file():
        _check_synthetic(root, scene, rep)
    return rep

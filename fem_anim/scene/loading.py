"""Making a :class:`Scene`: from a file, a TOML string or a dict, with ``--set`` overrides.

Every way in goes the same road, so a scene is checked once and the same way wherever it
comes from: parse the TOML (a file: a regular UTF-8 file of at most
:data:`~fem_anim.scene.constraints.MAX_FILE_BYTES`), apply ``--set KEY=VALUE`` overrides,
let ``solver.mode`` fill the solver keys the scene left out (:mod:`fem_anim.scene.modes`),
then validate (:mod:`fem_anim.scene.validation`). A failure is one
:class:`~fem_anim.errors.SceneError` line: where the scene came from, the key path, the
constraint and the value.
"""

from __future__ import annotations

import copy
import re
import stat
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from fem_anim.errors import SceneError
from fem_anim.errors import show_value as _show
from fem_anim.scene.consistency import check_render
from fem_anim.scene.constraints import MAX_FILE_BYTES
from fem_anim.scene.modes import apply_solver_mode
from fem_anim.scene.schema import SCHEMA
from fem_anim.scene.validation import validate_scene, validate_table

__all__ = ["Scene", "load_scene", "parse_override", "apply_override", "parse_toml",
           "validate_render", "default_scene_text"]


@dataclass(repr=False)
class Scene:
    """A validated scene: its tables as plain nested dictionaries, and where it came from.

    ``Scene(data)`` validates ``data`` exactly like :meth:`from_dict`; every key of the
    result is present (absent keys at their defaults), so code downstream reads
    ``scene["time"]["dt"]`` without a fallback.

    Args:
        data: The scene's tables, as a scene file would hold them.
        source: Where the scene came from, the first word of its error messages.
        base_dir: The folder that relative paths (``mesh.file``) are relative to (default:
            the working directory).

    Raises:
        SceneError: naming ``source``, the key path, the constraint and the value.

    Examples:
        >>> import fem_anim
        >>> scene = fem_anim.Scene({"time": {"dt": 0.01, "steps": 3}})
        >>> scene["time"]["steps"], scene["material"]["model"]
        (3, 'neohookean')
    """

    data: dict[str, Any]
    source: str = "<dict>"
    base_dir: Path = field(default_factory=Path.cwd)

    def __post_init__(self) -> None:
        self.data = _validated(_as_table(self.data, self.source), (), self.source)
        self.base_dir = Path(self.base_dir)

    @classmethod
    def _of(cls, data: dict[str, Any], source: str, base_dir: Path) -> Scene:
        """A Scene of already validated ``data`` (no second validation)."""
        scene = cls.__new__(cls)
        scene.data, scene.source, scene.base_dir = data, source, Path(base_dir)
        return scene

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], overrides: Sequence[str] = (), *,
                  source: str = "<dict>", base_dir: str | Path | None = None) -> Scene:
        """A scene from its tables as Python data, validated exactly like a file.

        Args:
            data: Tables as a scene file would hold them (``{"mesh": {"dim": 2}}``); not
                modified. A key given as ``None`` counts as absent.
            overrides: ``KEY=VALUE`` strings applied first, as ``--set`` does.
            source: The first word of error messages.
            base_dir: The folder that relative paths are relative to (default: the working
                directory).

        Returns:
            The validated scene.

        Raises:
            SceneError: ``"<dict>: KEY-PATH CONSTRAINT, got VALUE"``, the message a file
                with the same content gives after its file name.

        Examples:
            >>> import fem_anim
            >>> scene = fem_anim.Scene.from_dict({"mesh": {"dim": 2, "size": [1.0, 0.1]}})
            >>> scene.dim, scene["mesh"]["element_size"]
            (2, 0.05)
            >>> fem_anim.Scene.from_dict({"mesh": {"shape": "banana"}})
            Traceback (most recent call last):
            ...
            fem_anim.errors.SceneError: <dict>: mesh.shape must be one of box, sphere, \
cylinder, torus, capsule, file, sheet, got 'banana'
        """
        raw = _as_table(data, source)
        return cls._of(_validated(raw, overrides, source), source,
                       Path.cwd() if base_dir is None else Path(base_dir))

    @classmethod
    def from_toml(cls, text: str, overrides: Sequence[str] = (), *,
                  source: str = "<string>", base_dir: str | Path | None = None) -> Scene:
        """A scene from the text of a scene file.

        Args:
            text: TOML, as in a scene file.
            overrides: ``KEY=VALUE`` strings applied first, as ``--set`` does.
            source: The first word of error messages.
            base_dir: The folder that relative paths are relative to (default: the working
                directory).

        Returns:
            The validated scene.

        Raises:
            SceneError: for text that is not TOML, has no keys, or holds a bad key.

        Examples:
            >>> import fem_anim
            >>> scene = fem_anim.Scene.from_toml('''
            ... name = "drop"
            ... [mesh]
            ... dim = 2
            ... size = [0.5, 0.1]
            ... [gravity]
            ... acceleration = [0.0, -9.81]
            ... ''')
            >>> scene.name, scene["gravity"]["acceleration"]
            ('drop', [0.0, -9.81])
        """
        return cls._of(_parsed(text, f"scene {source}", overrides, source), source,
                       Path.cwd() if base_dir is None else Path(base_dir))

    @classmethod
    def load(cls, path: str | Path | None = None, overrides: Sequence[str] = ()) -> Scene:
        """A scene from a file (``None``: the default scene, a hanging beam).

        Args:
            path: The scene file; relative paths inside it are relative to its folder.
            overrides: ``KEY=VALUE`` strings (``"time.steps=10"``), as ``--set`` gives them.

        Returns:
            The validated scene.

        Raises:
            SceneError: naming the file, the key path, the constraint and the value.

        Examples:
            >>> import fem_anim
            >>> scene = fem_anim.Scene.load(None, ["time.steps=2"])
            >>> scene.name, scene["time"]["steps"]
            ('hanging_beam', 2)
        """
        return load_scene(path, overrides)

    def __getitem__(self, section: str) -> Any:
        return self.data[section]

    def get(self, section: str, default: Any = None) -> Any:
        """``scene[section]``, or ``default`` for an optional table the scene leaves out."""
        return self.data.get(section, default)

    def __repr__(self) -> str:
        return f"Scene(name={self.name!r}, source={self.source!r})"

    @property
    def name(self) -> str:
        return self.data["name"]

    @property
    def dim(self) -> int:
        return self.data["mesh"]["dim"]

    @property
    def damped(self) -> bool:
        """A ``[damping]`` section with a positive coefficient (alpha = beta = 0: no term)."""
        damping = self.data.get("damping")
        return damping is not None and (damping["alpha"] > 0 or damping["beta"] > 0)


def _as_table(data: Any, source: str) -> dict[str, Any]:
    """A deep copy of a scene given as Python data (the caller's dict is never changed)."""
    if not isinstance(data, Mapping):
        raise SceneError(f"{source}: a scene is a table of sections (a dict), got "
                         f"{_show(data)}")
    return copy.deepcopy(dict(data))


def _validated(raw: dict[str, Any], overrides: Sequence[str], source: str) -> dict[str, Any]:
    """The common road: no keys is an error, then overrides, the solver mode, validation."""
    if not raw:  # an empty scene is a mistake, not the defaults
        where = f"scene file {source}" if source[:1] != "<" else f"scene {source}"
        raise SceneError(f"{where} is empty (no keys)")
    for item in overrides:
        key_path, value = parse_override(item)
        apply_override(raw, key_path, value)
    apply_solver_mode(raw)  # solver.mode fills the solver keys the scene left out
    try:
        return validate_scene(raw)
    except SceneError as err:
        raise SceneError(f"{source}: {err}") from None


def _parsed(text: str, what: str, overrides: Sequence[str], source: str) -> dict[str, Any]:
    try:
        raw = parse_toml(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{what} is not valid TOML: {err}") from None
    return _validated(raw, overrides, source)


def default_scene_text() -> str:
    """The TOML text of the embedded default scene (the hanging beam)."""
    return resources.files("fem_anim").joinpath("default_scene.toml").read_text()


def parse_override(text: str) -> tuple[list[str], Any]:
    """Parse one ``--set KEY=VALUE``; the value is TOML, a bare word is taken as a string.

    Returns:
        The key path (``["pin", "0", "max"]``) and the value.

    Raises:
        SceneError: without ``=``, for a key that is not a dotted path, or a value that is
            neither TOML nor a bare word.
    """
    if "=" not in text:
        raise SceneError(f"--set expects KEY=VALUE, got {text!r}")
    key, raw = text.split("=", 1)
    path = key.strip().split(".")
    if not all(re.fullmatch(r"[\w-]+", part) for part in path):
        raise SceneError(f"--set key {key!r} is not a dotted key path")
    try:
        value = parse_toml(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        if raw.strip().replace("_", "").replace("-", "").isalnum():
            value = raw.strip()
        else:
            raise SceneError(f"--set {'.'.join(path)}: value {raw!r} is not valid TOML") \
                from None
    return path, value


def apply_override(data: dict, path: list[str], value: Any) -> None:
    """Set ``value`` at ``path`` in parsed scene tables (a number indexes an array).

    Raises:
        SceneError: when the path runs through a value that is not a table or an array.
    """
    node = data
    for i, part in enumerate(path[:-1]):
        if isinstance(node, list):
            if not part.isdecimal():
                raise SceneError(f"--set {'.'.join(path)}: {'.'.join(path[:i])} is a list; "
                                 f"give an entry number, e.g. {'.'.join(path[:i])}.0")
            idx = int(part)
            if idx >= len(node):
                raise SceneError(f"--set {'.'.join(path)}: there is no entry {idx} in "
                                 f"{'.'.join(path[:i])}")
            node = node[idx]
            if not isinstance(node, (dict, list)):
                raise SceneError(f"--set {'.'.join(path)}: {'.'.join(path[:i + 1])} is not a "
                                 "table")
            continue
        nxt = node.setdefault(part, {})
        if not isinstance(nxt, (dict, list)):
            raise SceneError(f"--set {'.'.join(path)}: {'.'.join(path[:i + 1])} is not a table")
        node = nxt
    if not isinstance(node, dict):
        raise SceneError(f"--set {'.'.join(path)}: cannot set a key inside a list")
    node[path[-1]] = value


def parse_toml(text: str) -> dict[str, Any]:
    """``tomllib.loads``, with its non-TOML failures turned into ``TOMLDecodeError``."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise tomllib.TOMLDecodeError("arrays or tables nested too deeply") from None
    except ValueError as err:  # an integer longer than Python converts (4300 digits)
        if isinstance(err, tomllib.TOMLDecodeError):
            raise
        raise tomllib.TOMLDecodeError(f"a number has too many digits ({err})".split(
            "; use sys.set_int_max_str_digits")[0]) from None


def _read_scene_file(p: Path) -> str:
    """The text of a scene file: a regular UTF-8 file of at most ``MAX_FILE_BYTES``."""
    try:
        mode = p.stat().st_mode
    except FileNotFoundError:
        raise SceneError(f"scene file {p} does not exist") from None
    except OSError as err:
        raise SceneError(f"scene file {p} cannot be read: {err.strerror}") from None
    if stat.S_ISDIR(mode):
        raise SceneError(f"scene file {p} is a directory")
    if not stat.S_ISREG(mode):  # a FIFO or device would block or never end
        raise SceneError(f"scene file {p} is not a regular file")
    try:
        with open(p, "rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as err:
        raise SceneError(f"scene file {p} cannot be read: {err.strerror}") from None
    if len(data) > MAX_FILE_BYTES:
        raise SceneError(f"scene file {p} is larger than {MAX_FILE_BYTES} bytes: not a scene")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise SceneError(f"scene file {p} is not UTF-8 text (byte {err.start}: "
                         f"{data[err.start:err.start + 1]!r})") from None
    return text


def load_scene(path: str | Path | None = None, overrides: Sequence[str] = ()) -> Scene:
    """Read, override and validate a scene file; ``path=None`` gives the default scene.

    Raises:
        SceneError: naming the file, key path, constraint and value.
    """
    if path is None:
        text, source, base = default_scene_text(), "<default scene>", Path.cwd()
    else:
        p = Path(path)
        text = _read_scene_file(p)
        source, base = str(p), p.resolve().parent
    return Scene._of(_parsed(text, f"scene file {source}", overrides, source), source, base)


def validate_render(saved: Mapping[str, Any] | None, overrides: Sequence[str] = ()
                    ) -> dict[str, Any]:
    """The ``[render]`` settings of a saved run, with ``--set render.KEY=VALUE`` applied.

    ``fem-anim render OUTDIR`` re-renders a run with the settings it was run with
    (``scene.json``), changed only by ``render.*`` overrides: the simulation is not redone,
    so other keys cannot change.

    Raises:
        SceneError: for an override outside ``render``, or a bad value (naming the key).
    """
    table = {"render": {k: v for k, v in (saved or {}).items() if v is not None}}
    for item in overrides:
        path, value = parse_override(item)
        if path[0] != "render" or len(path) != 2:
            raise SceneError(f"--set {'.'.join(path)}: only render.* keys can change when a "
                             "saved run is rendered again (run the scene to change others)")
        apply_override(table, path, value)
    render = validate_table("render", table["render"], SCHEMA["render"], "render")
    check_render(render)
    return render

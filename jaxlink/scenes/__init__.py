"""Built-in scenes: TOML files shipped inside the package.

Every scene file has a `[mechanism]` table with `name` and `description`; `jaxlink scenes`
lists them. A FILE argument on the command line is either a path or one of these names.

Code that belongs to one family of scenes lives beside them, in a scene module: its design
objectives and their defaults (`sewing_feed.py`: `feed`; `needle_dwell.py`: `dwell`), registered
by the objective registry (`jaxlink/optimize/objectives/__init__.py`) through each module's
`register_objectives`. Importing this package imports none of them.
"""

from __future__ import annotations

import pathlib

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

SCENE_DIR = pathlib.Path(__file__).resolve().parent


def scene_paths() -> dict[str, pathlib.Path]:
    """Name -> path of every built-in scene (name = file stem)."""
    return {p.stem: p for p in sorted(SCENE_DIR.glob("*.toml"))}


def describe(path: pathlib.Path) -> str:
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    return str(data.get("mechanism", {}).get("description", ""))


def resolve(name_or_path: str) -> pathlib.Path:
    """A path if it exists, else a built-in scene name; raises `MechanismError` otherwise."""
    from ..errors import MechanismError

    p = pathlib.Path(name_or_path)
    if p.is_file():
        return p
    if name_or_path not in scene_paths() and (p.suffix == ".toml" or "/" in name_or_path):
        raise MechanismError(f"no such file: {name_or_path}")
    return named(name_or_path, "is neither a file nor a built-in scene")


def named(name: str, what: str = "is not a built-in scene") -> pathlib.Path:
    """The file of the built-in scene `name`; a `MechanismError` with the closest name otherwise."""
    from ..errors import MechanismError

    scenes = scene_paths()
    if name in scenes:
        return scenes[name]
    import difflib

    close = difflib.get_close_matches(name, list(scenes), n=1)
    hint = f" — did you mean '{close[0]}'?" if close else ""
    raise MechanismError(f"'{name}' {what}{hint}; built-in scenes: " + ", ".join(scenes))


def copy(name: str, dest: str | pathlib.Path | None = None, *, force: bool = False) -> pathlib.Path:
    """Write the file of the built-in scene `name` to `dest` (default `NAME.toml` in the current
    folder; a folder: `NAME.toml` in it), to be edited (a `[study]` table added, dimensions
    changed) and given as FILE. A scene is one file (none refers to another). An existing file is
    refused unless `force`. Returns the path written."""
    from ..errors import MechanismError

    src = named(name)
    out = pathlib.Path(dest) if dest is not None else pathlib.Path(src.name)
    if out.is_dir():
        out = out / src.name
    if out.exists() and not force:
        raise MechanismError(f"{out} exists: give --force to overwrite it, or another DEST")
    out.write_bytes(src.read_bytes())
    return out

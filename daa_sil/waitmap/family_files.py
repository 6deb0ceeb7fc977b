"""Wait-map family directories: one map file per turn rate (:mod:`daa_sil.waitmap.store`) plus ``family.json``.

``family.json`` (:func:`write_family_index`): ``family_hash`` (the hash of the grid, the parameters and the
turn-rate list, :func:`~daa_sil.waitmap.model.params_hash`), ``turn_rates_deg`` (that list) and per map
its ``turn_rate_deg``, ``file``, ``content_hash`` and ``bytes``. The index is not trusted as it stands:
:func:`check_family` checks it against its maps without reading their arrays (milliseconds), and
:func:`load_family` then reads each map with its zip CRC-32s verified instead of recomputing the
SHA-256 (see docs/waitmap.md, "The cache").
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from ..errors import FileFormatError, UsageError
from daa_sil.files import atomic_write_json
from .lookup import WaitMapFamily
from .model import FORMAT_VERSION, settings_hash
from .store import load, map_filename, read_meta, save
from ..errors import OutputError

FAMILY_INDEX = "family.json"


def save_family(fam: WaitMapFamily, directory: "str | os.PathLike", overwrite: bool = False,
                family_hash: str = "") -> list[Path]:
    """Write every map plus ``family.json`` into ``directory``; returns the map paths.
    ``family_hash`` defaults to the hash of the family's grid, parameters and (sorted) turn rates."""
    d = Path(directory)
    names = [map_filename(m.turn_rate_deg) for m in fam.maps]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise UsageError(f"two maps of the family would share the file name {dup}; turn rates must differ "
                         f"by at least 0.1 deg/s")
    targets = [d / n for n in names] + [d / FAMILY_INDEX]
    if not overwrite:
        clash = [p for p in targets if p.exists()]
        if clash:
            raise OutputError(f"{clash[0]} exists; refusing to overwrite (use --force or another --out)")
    paths = [save(m, d / map_filename(m.turn_rate_deg), overwrite=True) for m in fam.maps]
    rates = [float(m.turn_rate_deg) for m in fam.maps]
    write_family_index(d, [(m.turn_rate_deg, p, m.content_hash) for m, p in zip(fam.maps, paths)],
                       family_hash or settings_hash(fam.grid.to_dict()["axes"], fam.params.to_dict(), rates),
                       rates)
    return paths


# --- the family index ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class IndexEntry:
    """One map of a family index: its condition (deg/s), file name, content hash and size (bytes;
    None in an index written before sizes were recorded)."""

    turn_rate_deg: float
    file: str
    content_hash: str
    size: "int | None"


@dataclass(frozen=True)
class FamilyIndex:
    """``family.json``: the family hash, the turn rates it was computed over (in that order) and
    the maps."""

    family_hash: str
    turn_rates_deg: tuple
    maps: tuple


def write_family_index(directory: "str | os.PathLike", members: Sequence, family_hash: str,
                       turn_rates: Sequence[float]) -> Path:
    """Write ``family.json`` atomically. ``members`` are ``(turn rate deg/s, map path, content hash)``;
    each file's size is recorded too. ``turn_rates`` is the list ``family_hash`` was computed over."""
    d = Path(directory)
    entries = sorted(((float(r), Path(p), h) for r, p, h in members), key=lambda e: e[0])
    return atomic_write_json(d / FAMILY_INDEX, {
        "format": FORMAT_VERSION, "family_hash": family_hash,
        "turn_rates_deg": [float(r) for r in turn_rates],
        "maps": [{"turn_rate_deg": r, "file": p.name, "content_hash": h, "bytes": (d / p.name).stat().st_size}
                 for r, p, h in entries]})


def _number(v) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(v)
    return float(v)


def read_family_index(directory: "str | os.PathLike") -> FamilyIndex:
    """Parse ``family.json`` and check it on its own: one entry per turn rate, each naming the file
    :func:`map_filename` gives, and the same rates as ``turn_rates_deg``. FileFormatError otherwise."""
    idx = Path(directory) / FAMILY_INDEX
    try:
        info = json.loads(idx.read_text(encoding="utf-8"))
        maps = tuple(IndexEntry(_number(e["turn_rate_deg"]), str(e["file"]), str(e["content_hash"]),
                                None if e.get("bytes") is None else int(e["bytes"])) for e in info["maps"])
        listed = info.get("turn_rates_deg")
        rates = tuple(_number(r) for r in listed) if listed is not None else tuple(e.turn_rate_deg for e in maps)
        fhash = str(info.get("family_hash") or "")
    except FileNotFoundError:
        raise FileFormatError(f"{idx} does not exist") from None
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError):
        raise FileFormatError(f"{idx}: not a valid wait-map family index") from None
    if info.get("format") != FORMAT_VERSION:
        raise FileFormatError(f"{idx}: unsupported format {info.get('format')!r}; this version reads {FORMAT_VERSION!r}")
    if not maps:
        raise FileFormatError(f"{idx}: lists no wait maps")
    names = [map_filename(e.turn_rate_deg) for e in maps]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise FileFormatError(f"{idx}: lists the map {dup} more than once")
    bad = next((e for e, n in zip(maps, names) if e.file != n), None)
    if bad is not None:
        raise FileFormatError(f"{idx}: the {bad.turn_rate_deg:+g} deg/s map is {map_filename(bad.turn_rate_deg)}, "
                              f"not {bad.file!r}")
    if sorted(rates) != sorted(e.turn_rate_deg for e in maps):
        raise FileFormatError(f"{idx}: lists the maps {_rates_text(e.turn_rate_deg for e in maps)} deg/s, but its "
                              f"family hash covers {_rates_text(rates)} deg/s")
    return FamilyIndex(fhash, rates, maps)


def _rates_text(rates) -> str:
    return ", ".join(f"{r:+g}" for r in sorted(rates))


def check_family(directory: "str | os.PathLike", turn_rates: "Sequence[float] | None" = None,
                 family_hash: "str | None" = None) -> FamilyIndex:
    """The cheap check of a family directory, without reading any array (milliseconds for the
    99 MB default family). FileFormatError naming the first problem.

    * the index on its own (:func:`read_family_index`): no map missing from or repeated in it;
    * ``turn_rates`` (deg/s) and ``family_hash``, when given (the cache knows both), are the index's;
    * every file is there with the recorded size, and declares (in its CRC-checked metadata) the
      recorded content hash and turn rate;
    * all maps share one grid and parameter set, and the hash of those with the index's turn rates
      is the index's ``family_hash``: the index describes exactly these maps.

    What it cannot see is damage inside an array whose size is unchanged; :func:`load_family`
    catches that when it reads the arrays (zip CRC-32 per array). A caller that only needs the
    hashes (e.g. to record them) may take them from the index this returns."""
    d = Path(directory)
    if not d.is_dir():
        raise FileFormatError(f"wait-map family directory {d} does not exist")
    idx = read_family_index(d)
    where = d / FAMILY_INDEX
    if turn_rates is not None and sorted(float(r) for r in turn_rates) != sorted(idx.turn_rates_deg):
        raise FileFormatError(f"{where}: lists the maps {_rates_text(idx.turn_rates_deg)} deg/s; this family "
                              f"needs {_rates_text(turn_rates)} deg/s")
    if family_hash is not None and idx.family_hash != family_hash:
        raise FileFormatError(f"{where}: family hash {idx.family_hash[:12] or 'none'}... is not this cache "
                              f"entry's {family_hash[:12]}...")
    metas = []
    for e in idx.maps:
        f = d / e.file
        try:
            size = f.stat().st_size
        except FileNotFoundError:
            raise FileFormatError(f"{f}: the {e.turn_rate_deg:+g} deg/s map listed in {FAMILY_INDEX} does not "
                                  f"exist") from None
        if e.size is not None and size != e.size:
            raise FileFormatError(f"{f}: {size} bytes, {FAMILY_INDEX} records {e.size} (truncated or replaced)")
        meta = read_meta(f)
        if meta.get("content_hash") != e.content_hash:
            raise FileFormatError(f"{f}: its content hash is not the one {FAMILY_INDEX} records (replaced or edited)")
        if meta.get("turn_rate_deg") != e.turn_rate_deg:
            raise FileFormatError(f"{f}: a map for {meta.get('turn_rate_deg')!r} deg/s, listed as {e.turn_rate_deg:+g}")
        metas.append(meta)
    axes, params = metas[0].get("grid", {}).get("axes"), metas[0].get("params")
    if any(m.get("grid", {}).get("axes") != axes or m.get("params") != params for m in metas):
        raise FileFormatError(f"{d}: the maps have different grids or parameters; they are not one family")
    if idx.family_hash and settings_hash(axes, params, idx.turn_rates_deg) != idx.family_hash:
        raise FileFormatError(f"{where}: its family hash does not match the grid, parameters and turn rates of its maps")
    return idx


def load_family(directory: "str | os.PathLike", turn_rates: "Sequence[float] | None" = None,
                family_hash: "str | None" = None) -> WaitMapFamily:
    """Load a family directory: after :func:`check_family` (``turn_rates`` and ``family_hash`` as
    there), each map read with its zip CRC-32s verified and the content hash the index records.
    FileFormatError on any problem, including a directory without ``family.json``."""
    d = Path(directory)
    if not d.is_dir():
        raise UsageError(f"wait-map family directory {d} does not exist")
    if (d / FAMILY_INDEX).is_file():
        idx = check_family(d, turn_rates, family_hash)
        maps = [load(d / e.file, expected_hash=e.content_hash) for e in idx.maps]
    elif any(d.glob("waitmap_turn*.npz")):  # maps without an index: which ones belong is unknown
        raise FileFormatError(f"{d}: maps but no {FAMILY_INDEX} (an interrupted 'daa-sil waitmap build'? build "
                              f"again, or pass one map file)")
    else:
        raise FileFormatError(f"{d}: no wait maps found")
    maps = sorted(maps, key=lambda m: m.turn_rate_deg)
    g0 = maps[0].grid.to_dict()["axes"]
    if any(m.grid.to_dict()["axes"] != g0 for m in maps):
        raise FileFormatError(f"{d}: maps on different grids cannot form one family")
    return WaitMapFamily(maps)

"""The report's input: campaign directories (or tables) read into blocks, one block per named
reading, with the optional recounts of a directory under another counting (``--recount``)."""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

from daa_sil.errors import FileFormatError, UsageError
from daa_sil.files import local_file
from daa_sil.study.analysis.counting import (
    DECISION_COLUMNS,
    CountingRules,
    counting_options,
)
from daa_sil.study.analysis.metrics import (
    as_columns,
)


def _read_parquet(path: Path, columns=None):
    import pyarrow as pa  # lazy: start-up time
    import pyarrow.parquet as pq  # lazy: start-up time

    try:
        with local_file(path) as fh:
            return pq.read_table(fh, columns=columns)
    except (OSError, pa.ArrowException, ValueError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise FileFormatError(f"{path} is not a readable Parquet file: {msg}") from None


def _concat(tables, what):
    import pyarrow as pa  # lazy: start-up time

    try:
        return pa.concat_tables(tables, promote_options="default")
    except (pa.ArrowException, TypeError) as exc:
        raise FileFormatError(f"{what} have incompatible schemas: {str(exc).splitlines()[0]}") from None


def load_results(src) -> dict:
    """The per-encounter table of ``src`` (directory, Parquet file list, Table or dict) as columns."""
    if isinstance(src, (str, os.PathLike)):
        d = Path(src)
        if not d.exists():
            raise FileFormatError(f"{d}: no such results directory")
        if d.is_file():
            files = [d]
        else:
            files = sorted(d.glob("*/encounters-*.parquet"))
            if not files:
                raise FileFormatError(f"{d} holds no <group>/encounters-*.parquet results")
            from daa_sil.study.campaign.files import verify_chunks  # lazy: start-up time

            verify_chunks(d)  # a chunk damaged on disk is named here, not read as wrong numbers
    elif isinstance(src, (list, tuple)) and src and all(isinstance(s, (str, os.PathLike)) for s in src):
        files = [Path(s) for s in src]
        for f in files:
            if not f.is_file():
                raise FileFormatError(f"{f}: no such results file")
    else:
        return as_columns(src)
    table = _concat([_read_parquet(f) for f in files], "result files")
    if table.num_rows == 0:
        raise FileFormatError(f"{src}: the result files hold no encounters")
    return as_columns(table)


def load_decisions(d: Path):
    """The decision tables of directory ``d`` restricted to the provenance columns, or None when
    there are none or they carry neither ``decided_by`` nor ``in_box``."""
    import pyarrow.parquet as pq  # lazy: start-up time

    files = sorted(Path(d).glob("*/decisions-*.parquet"))
    if not files:
        return None
    try:
        with local_file(files[0]) as fh:
            names = pq.read_schema(fh).names
    except Exception as exc:  # noqa: BLE001 -- pyarrow raises several types for a bad footer
        raise FileFormatError(f"{files[0]} is not a readable Parquet file: {str(exc).splitlines()[0]}") from None
    if not any(c in names for c in ("decided_by", "in_box")):
        return None
    cols = [c for c in DECISION_COLUMNS if c in names]
    return _concat([_read_parquet(f, cols) for f in files], "decision files")


@dataclass(frozen=True)
class Block:
    """One column block of the report: a reading and its results."""

    label: str
    reading: CountingRules
    enc: dict
    dec: object = None
    meta: "dict | None" = None

    @property
    def seed(self):
        return (self.meta or {}).get("seed")

    @property
    def n_config(self):
        return (self.meta or {}).get("n_encounters")


def load_block(src) -> Block:
    """A reading from a campaign directory (or, for old callers, any :func:`load_results` source)."""
    meta = {}
    dec = None
    name, settings, source = "default", {}, ""
    if isinstance(src, (str, os.PathLike)) and Path(src).is_dir():
        d = Path(src)
        source = str(d)
        if (d / "campaign.json").is_file():
            from daa_sil.study.campaign.files import load_campaign_json  # lazy: start-up time

            cj = load_campaign_json(d)
            cfg = cj.get("config", {})
            name = str(cfg.get("reading") or "default")
            settings = cfg.get("readings") or {}
            if not isinstance(settings, dict):
                raise FileFormatError(f"{d / 'campaign.json'}: config.readings must be a mapping, got "
                                      f"{type(settings).__name__}")
            meta = {"seed": cfg.get("seed", cj.get("seed")), "n_encounters": cfg.get("n_encounters"),
                    "preset": cfg.get("preset", cj.get("preset")), "groups": cfg.get("groups"),
                    "status": cj.get("status"), "seeds": cfg.get("seeds"), "dt_s": cfg.get("dt_s"),
                    "basis": cj.get("basis")}
        dec = load_decisions(d)
    enc = load_results(src)
    if not enc or len(next(iter(enc.values()))) == 0:
        raise FileFormatError(f"{src if isinstance(src, (str, os.PathLike)) else 'results'}: no encounters")
    return Block(name, CountingRules(name, dict(settings), source), enc, dec, meta)


def parse_recount(text: str) -> tuple[str, dict]:
    """``NAME:key=value[,key=value]`` -> (name, counting settings); UsageError naming what is allowed."""
    if ":" not in text:
        raise UsageError(f"--recount expects NAME:key=value[,key=value], got {text!r}")
    name, _, body = text.partition(":")
    name = name.strip()
    if not name:
        raise UsageError(f"--recount {text!r}: the name before ':' is empty")
    out = {}
    options = counting_options()
    for item in filter(None, (p.strip() for p in body.split(","))):
        k, eq, v = item.partition("=")
        k, v = k.strip(), v.strip()
        if not eq or k not in options:
            raise UsageError(f"--recount {text!r}: {item!r} is not a counting setting; allowed keys: "
                             f"{', '.join(options)}")
        if v not in options[k]:
            raise UsageError(f"--recount {text!r}: {k}={v!r} is not allowed; {k} is one of "
                             f"{', '.join(options[k])}")
        out[k] = v
    if not out:
        raise UsageError(f"--recount {text!r}: no setting given")
    return name, out


def build_blocks(sources, recount: Sequence[str] = ()) -> list[Block]:
    """One block per source, labelled by reading name (``(seed S)`` and ``#k`` added on clashes), plus
    one derived block per source and ``--recount`` entry (same results, other counting)."""
    srcs = list(sources) if isinstance(sources, (list, tuple)) and sources and all(
        isinstance(s, (str, os.PathLike)) and Path(s).is_dir() for s in sources) else [sources]
    blocks = [load_block(s) for s in srcs]
    derived = []
    for spec in recount:
        name, settings = parse_recount(spec)
        for b in blocks:
            st = {**b.reading.settings, **settings}
            if st == b.reading.settings:  # the source already counts this way: nothing to add
                continue
            how = ", ".join(f"{k}={v}" for k, v in settings.items())
            st["description"] = f"{b.reading.settings.get('description', b.reading.name)}; recounted with {how}"
            derived.append(replace(b, label=f"{b.label}+{name}", reading=CountingRules(f"{b.reading.name}+{name}", st,
                                                                              b.reading.source)))
    return unique_labels(blocks + derived)


def unique_labels(blocks: "list[Block]") -> "list[Block]":
    """The blocks with unique labels: on a clash the campaign seed is added, and the number of
    encounters too when one reading was run on two sizes of one seed; ``#k`` as a last resort."""
    labels = [b.label for b in blocks]
    out = []
    for b in blocks:
        lab = b.label
        if labels.count(lab) > 1 and b.seed is not None:
            same_seed = [o for o in blocks if o.label == b.label and o.seed == b.seed]
            if len(same_seed) > 1 and b.n_config is not None:  # e.g. one reading on two sizes of one seed
                lab = f"{lab} (seed {b.seed}, {b.n_config:,} enc.)"
            else:
                lab = f"{lab} (seed {b.seed})"
        k = 2
        base = lab
        while lab in [o.label for o in out]:
            lab = f"{base} #{k}"
            k += 1
        out.append(replace(b, label=lab))
    return out


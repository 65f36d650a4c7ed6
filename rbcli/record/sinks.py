"""Choose a file sink from the output path's extension (imports the writer library lazily)."""

from __future__ import annotations

from pathlib import Path

from rbcli.record.frame import Sink

FORMATS = {".mcap": "mcap", ".rrd": "rerun"}


def output_format(path: str | Path) -> str:
    """'mcap' or 'rerun' from the extension; ValueError for anything else."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"output {str(path)!r}: unknown format {suffix or '(no extension)'!r}; use .mcap or .rrd")
    return FORMATS[suffix]


def open_file_sink(path: str | Path, *, compression: str = "zstd") -> Sink:
    """SinkMcap (with this chunk compression: zstd, lz4 or none) or SinkRerun for the path."""
    if output_format(path) == "mcap":
        from rbcli.record.mcap_sink import SinkMcap

        return SinkMcap(Path(path), compression=compression)
    from rbcli.record.rerun_sink import SinkRerun

    return SinkRerun(Path(path))

"""``glassdist serve``: the local web application (see :mod:`glassdist.web`)."""

from __future__ import annotations

from pathlib import Path

from ..validation import Range, number_option

__all__ = ["register", "run"]


def _port(text: str) -> int:
    import argparse

    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got '{text}'") from None
    if not 0 < port < 65536:
        raise argparse.ArgumentTypeError(f"must be between 1 and 65535, got {text}")
    return port


def register(subparsers):
    """Add the ``serve`` sub-command."""
    p = subparsers.add_parser(
        "serve", help="local web application: upload a photo, see the maps and verdict, download the report",
        description="Start a web server for glassdist analyze: upload a photo (and a reference, mask, specification), "
        "see the heatmaps, statistics, verdict and warnings, download the report and exports. Each job runs "
        "'glassdist analyze' in its own private temporary folder, removed when the server stops. Listens on "
        "this machine only unless --host says otherwise (there is no login). Needs glassdist[web].")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=_port, default=8000, help="port (default 8000)")
    p.add_argument("--max-upload-mb", type=number_option(Range(1e-3, 1e5, unit="MB")), default=64.0,
                   help="largest accepted upload per file, MB (default 64)")
    p.add_argument("--max-jobs", type=int, default=20, help="jobs kept (older ones and their files are removed; default 20)")
    p.add_argument("--max-disk-mb", type=number_option(Range(1.0, 1e9, unit="MB")), default=2048.0,
                   help="disk budget of the kept jobs, MB: the oldest are removed while their files take more (default 2048)")
    p.add_argument("--db", metavar="PATH|URL", help="history database the jobs are recorded in and the history page "
                   "shows (default: $GLASSDIST_DB, else ~/.local/share/glassdist/history.sqlite)")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """Serve until interrupted."""
    from ..errors import InputError

    try:
        import fastapi  # noqa: F401
        import uvicorn  # noqa: F401

        from . import serve
    except ImportError:
        raise InputError("glassdist serve needs the web extra: pip install 'glassdist[web]'") from None
    if not args.max_upload_mb > 0 or args.max_jobs < 1:
        raise InputError("--max-upload-mb must be positive and --max-jobs at least 1")
    db = args.db if args.db is None or "://" in args.db else str(Path(args.db).absolute())  # jobs run elsewhere
    serve(args.host, args.port, max_upload_mb=args.max_upload_mb, max_jobs=args.max_jobs, max_disk_mb=args.max_disk_mb,
          db=db)
    return 0

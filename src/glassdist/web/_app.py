"""The FastAPI application: server-rendered pages (Jinja2), one job per upload, a status endpoint."""

from __future__ import annotations

import contextlib
import io
import logging
import re
import sys
import zipfile
from pathlib import Path
from urllib.parse import quote

from fastapi import FastAPI, Request, UploadFile
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse, Response
from fastapi.templating import Jinja2Templates

from .._version import __version__
from ..errors import InputError
from ._jobs import LABELS, ROLES, JobStore, display_name, form_language, stored_name

__all__ = ["create_app", "serve"]

logger = logging.getLogger(__name__)

_TEMPLATES = Jinja2Templates(directory=str(Path(__file__).with_name("templates")))
_TEMPLATES.env.globals["labels"] = LABELS  # the form's words, on every page that names a field
#: Figures shown on the result page, in this order, when the analysis wrote them.
_FIGURES = (("phi_eff.png", "phi_eff (mD)"), ("phi_shear.png", "phi_shear (mD)"), ("axis.png", "astigmatism axis"),
            ("uncertainty.png", "standard uncertainty of phi_eff (mD)"),
            ("surface_height.png", "reflection: front-face height (µm)"),
            ("surface_slope.png", "reflection: front-face slope (mrad)"),
            ("input_region.png", "photo, analysed region outlined"))
#: Figures after the threshold masks, in boxes twice as wide: their legends and panels need the room.
_WIDE_FIGURES = (("quality.png", "quality: why each pixel is analysed or not"), ("histograms.png", "histograms"))
_MASK = re.compile(r"mask_(?P<channel>[a-z_]+?)_(?P<limit>[-+0-9.e]+)mD\.png")
_DOWNLOADS = (("report.html", "HTML report"), ("fields.npz", "fields (NPZ)"), ("statistics.csv", "statistics (CSV)"),
              ("summary.json", "summary (JSON)"), ("result.npz", "result.npz"))


class UploadTooLarge(InputError):
    """An upload over the size limit."""


async def _save_upload(store: JobStore, job, role: str, upload: UploadFile) -> None:
    head = await upload.read(16)
    if not head:
        return  # the field was left empty
    name = stored_name(role, head, upload.filename)
    job.names[role], job.display[role] = name, display_name(upload.filename, role)
    size, chunk = 0, head
    with open(job.folder / name, "wb") as fh:
        while chunk:
            size += len(chunk)
            if size > store.max_upload_bytes:
                raise UploadTooLarge(f"'{job.display[role]}' is larger than the {store.max_upload_bytes / 2**20:g} MB "
                                     "upload limit; send a smaller file (or start the server with a larger --max-upload-mb)")
            fh.write(chunk)
            chunk = await upload.read(1 << 20)


def create_app(*, public_host: str | None = None, **store_options) -> FastAPI:
    """The application; ``store_options`` go to :class:`JobStore`.

    ``public_host``: the address the server listens on when it is not local (a warning on every page).
    """
    store = JobStore(**store_options)

    @contextlib.asynccontextmanager
    async def lifespan(app):
        yield
        store.close()  # every job folder is removed when the server stops

    app = FastAPI(title="glassdist", version=__version__, lifespan=lifespan, docs_url=None, redoc_url=None)
    app.state.store = store
    pages = _Pages(store, public_host)
    _add_upload_routes(app, store, pages)
    _add_job_routes(app, store, pages)
    _add_history_routes(app, store, pages)
    return app


class _Pages:
    """The templates rendered with what every page shows: version, public-address warning, upload limit."""

    def __init__(self, store: JobStore, public_host: str | None):
        self.store, self.public_host = store, public_host

    def page(self, request, name, status_code=200, **context):
        context.update(version=__version__, public_host=self.public_host,
                       max_upload_mb=self.store.max_upload_bytes / 2**20, max_jobs=self.store.max_jobs,
                       max_disk_mb=self.store.max_disk_bytes / 2**20)
        return _TEMPLATES.TemplateResponse(request, name, context, status_code=status_code)

    def index(self, request, *, error="", status_code=200, form=None):
        return self.page(request, "index.html", status_code, jobs=self.store.recent(), error=error, form=form or {})


def _add_upload_routes(app: FastAPI, store: JobStore, pages: _Pages) -> None:
    """``GET /`` (the upload form and the recent jobs) and ``POST /jobs`` (one job per upload)."""
    # several files per request, plus the form itself
    max_request = len(ROLES) * store.max_upload_bytes + (1 << 20)
    index = pages.index

    @app.get("/", response_class=HTMLResponse)
    async def home(request: Request):
        return index(request)

    @app.post("/jobs")
    async def create_job(request: Request):
        length = request.headers.get("content-length")
        if length and length.isdigit() and int(length) > max_request:
            return index(request, status_code=413, error=f"the upload is larger than the {store.max_upload_bytes / 2**20:g} "
                                                        "MB limit per file; send smaller files")
        form = await request.form()
        fields = {k: v for k, v in form.items() if isinstance(v, str)}
        job = store.new_job()
        try:
            for role in ROLES:
                upload = form.get(role)
                if upload is not None and not isinstance(upload, str):
                    await _save_upload(store, job, role, upload)
            store.submit(job, fields)
        except InputError as exc:
            store.discard(job)
            return index(request, status_code=413 if isinstance(exc, UploadTooLarge) else 400, error=str(exc),
                         form=fields)
        finally:
            await form.close()
        return RedirectResponse(f"/jobs/{job.id}", status_code=303)


def _add_job_routes(app: FastAPI, store: JobStore, pages: _Pages) -> None:
    """A job's page, status, files and outputs archive under ``/jobs/{job_id}``; an unknown one is a 404 page."""
    page = pages.page

    def get_job(job_id):
        job = store.get(job_id)
        if job is None:
            raise _NotFound()
        return job

    @app.get("/jobs/{job_id}", response_class=HTMLResponse)
    async def job_page(request: Request, job_id: str):
        job = get_job(job_id)
        # only files that are there are linked or shown (a job without the report has no report link)
        outputs = {name for name in job.outputs() if job.output_path(name) is not None}
        summary = job.summary() if job.state == "done" else {}
        return page(request, "job.html", job=job, summary=summary, verdict=summary.get("verdict"),
                    warnings=[form_language(w, job.names, job.display) for w in summary.get("warnings") or []],
                    statistics=(summary.get("a4") or {}).get("statistics") or summary.get("statistics") or {},
                    figures=[(f, t, "") for f, t in _FIGURES if f in outputs] + _mask_figures(outputs)
                    + [(f, t, "wide") for f, t in _WIDE_FIGURES if f in outputs],
                    downloads=[(f, t) for f, t in _DOWNLOADS if f in outputs], report="report.html" in outputs)

    @app.get("/jobs/{job_id}/status")
    async def job_status(job_id: str):
        return JSONResponse(get_job(job_id).status())

    @app.get("/jobs/{job_id}/files/{name:path}")
    async def job_file(job_id: str, name: str, download: bool = False):
        path = get_job(job_id).output_path(name)
        if path is None:
            raise _NotFound()
        kind = "attachment" if download else "inline"
        return FileResponse(path, filename=Path(name).name, content_disposition_type=kind)

    @app.get("/jobs/{job_id}/outputs.zip")
    async def job_zip(job_id: str):
        job = get_job(job_id)
        if job.state != "done":
            raise _NotFound()
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in job.outputs():
                path = job.output_path(name)
                if path is not None:
                    zf.write(path, name)
        headers = {"Content-Disposition": f'attachment; filename="glassdist-{job.id}.zip"'}
        return Response(buf.getvalue(), media_type="application/zip", headers=headers)

    @app.exception_handler(_NotFound)
    async def not_found(request: Request, exc):
        return page(request, "index.html", 404, jobs=store.recent(), form={},
                    error="no such job or file (jobs are kept until the server stops or newer ones replace them)")


class _NotFound(Exception):
    pass


def _mask_figures(outputs) -> list[tuple[str, str, str]]:
    """The threshold masks among ``outputs``, by channel and limit: (file, caption, box class)."""
    masks = [(m.group("channel"), float(m.group("limit")), name) for name in outputs if (m := _MASK.fullmatch(name))]
    return [(name, f"|{channel}| over {limit:g} mD: red", "") for channel, limit, name in sorted(masks)]


#: the history page's filters (query parameters), as ``glassdist history`` options
_HISTORY_FILTERS = ("pane_id", "lot", "site", "operator", "verdict", "since", "until", "zone", "statistic")
_HISTORY_ROWS = 500


def _history_filters(request: Request) -> dict:
    return {k: v.strip() for k in _HISTORY_FILTERS if (v := request.query_params.get(k, "")).strip()}


def _unit(rows: list[dict]) -> str:
    """The unit of the selected statistic: the records' own where they state it, else mD (the history's default)."""
    return ", ".join(sorted({str(r["unit"]) for r in rows if r.get("unit")})) or "mD"


def _add_history_routes(app: FastAPI, store: JobStore, pages: _Pages) -> None:
    """``GET /history`` (the recorded runs, filtered, newest last) and ``GET /history/chart.png`` (their control chart)."""
    from starlette.concurrency import run_in_threadpool

    from ..history import history as read_history

    def records(filters):
        return read_history(store.db, as_frame=False, **filters)

    @app.get("/history", response_class=HTMLResponse)
    async def history_page(request: Request):
        filters = _history_filters(request)
        try:
            rows = await run_in_threadpool(records, filters)
            error = ""
        except InputError as exc:
            rows, error = [], str(exc)
        shown = rows[-_HISTORY_ROWS:]
        for r in shown:  # a web job still kept by this server links to its page
            r["job_link"] = f"/jobs/{r['job']}" if r["source"] == "web" and r["job"] and store.get(r["job"]) else ""
        lots = sorted({r["lot"] for r in rows if r["lot"]})
        query = "&".join(f"{k}={quote(v)}" for k, v in filters.items())
        return pages.page(request, "history.html", status_code=400 if error else 200, rows=shown, total=len(rows),
                          filters=filters, error=error, lots=lots, chart=f"/history/chart.png?{query}" if lots else "",
                          label=f"{rows[0]['statistic']} ({rows[0]['zone']})" if rows else "",
                          unit=_unit(rows))

    @app.get("/history/chart.png")
    async def history_chart(request: Request):
        from ..history import plot_trends, trends
        from ..report.figures import figure_png

        filters = _history_filters(request)

        def draw():
            rows = records(filters)
            label = f"{rows[0]['statistic']} ({rows[0]['zone']})" if rows else "value"
            return figure_png(plot_trends(trends(rows), label=label), dpi=110)  # 9 in: 990 px, shown whole

        try:
            png = await run_in_threadpool(draw)
        except InputError:
            raise _NotFound() from None
        return Response(png, media_type="image/png")


def serve(host: str = "127.0.0.1", port: int = 8000, **options) -> None:
    """Run the application with uvicorn until interrupted; warns on stderr when not bound to this machine only."""
    import uvicorn

    from . import LOCAL_HOSTS

    public = host not in LOCAL_HOSTS
    if public:
        print(f"glassdist serve: warning: listening on {host}:{port}, reachable from other machines; anyone who "
              "can reach it can upload photos and run analyses (there is no login). Use --host 127.0.0.1 to keep "
              "it on this machine.", file=sys.stderr)
    app = create_app(public_host=f"{host}:{port}" if public else None, **options)
    print(f"glassdist {__version__}: open http://{'localhost' if not public else host}:{port}/ (Ctrl-C stops)",
          file=sys.stderr)
    uvicorn.run(app, host=host, port=port, log_level="warning")

"""A local web application for in-situ inspection (optional extra ``glassdist[web]``).

``glassdist serve`` starts it: upload a photo (and optionally a reference, a mask and
an acceptance specification), type the pitch and distance, and see the heatmaps,
statistics, verdict and warnings; download the HTML report and the exports. Each job
runs the ``glassdist analyze`` command in its own process inside a private temporary
folder, so the page shows exactly what the command line writes, with the same
validation, limits and one-line errors. FastAPI/Starlette and uvicorn are imported
only when the application is created. See ``docs/user-guide/web-app.md``.
"""

from ._jobs import Job, JobStore

__all__ = ["create_app", "serve", "Job", "JobStore", "LOCAL_HOSTS"]

#: Host names that only this machine can reach.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def create_app(**kwargs):
    """The ASGI application (FastAPI); keyword arguments as :class:`JobStore`.

    Returns
    -------
    fastapi.FastAPI
    """
    from ._app import create_app as _create

    return _create(**kwargs)


def serve(host: str = "127.0.0.1", port: int = 8000, **kwargs) -> None:
    """Serve the application with uvicorn until interrupted (see :func:`create_app`)."""
    from ._app import serve as _serve

    _serve(host, port, **kwargs)

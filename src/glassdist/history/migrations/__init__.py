"""Alembic migration environment of the history database (``glassdist.history.store`` runs it)."""

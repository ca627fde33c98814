"""``python -m glassdist``: the command line (:func:`glassdist.cli.main`)."""

from .cli import main

raise SystemExit(main())

"""``python -m bayes_roadload ...`` runs the command-line interface (same as ``bayes-roadload``)."""

from .cli import main

raise SystemExit(main())

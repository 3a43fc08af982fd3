"""``python -m jaxtrack`` runs the command line (the same as the ``jaxtrack`` script)."""

from .cli import main

raise SystemExit(main())

"""``python -m softgrains``: the same as the ``softgrains`` command."""

from softgrains.cli import main

raise SystemExit(main())

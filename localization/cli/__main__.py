"""``python -m localization.cli`` = ``appearance-nav``."""

from localization.cli import main

raise SystemExit(main())

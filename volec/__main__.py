"""`python -m volec` is the same as the `volec` console script."""

from volec.cli import main

raise SystemExit(main())

"""``python -m gcs`` = ``daa-gcs``."""

import sys

from gcs.cli import main

sys.exit(main())

"""``python -m pwa_pipeline``: the command line of `pwa_pipeline.orchestration.cli`."""

import sys

from .orchestration.cli import main

if __name__ == "__main__":
    sys.exit(main())

import sys

from parsolve.cli import main

sys.exit(main())

import sys

from antarium.cli import main

sys.exit(main())

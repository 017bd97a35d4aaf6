import sys

from mexone.cli import main

sys.exit(main())

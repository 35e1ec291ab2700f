import sys

from amprep.cli import main

sys.exit(main())

import sys

from telethermal.cli import main

sys.exit(main())

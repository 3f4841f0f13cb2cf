import sys

from fourd.cli import main

sys.exit(main())

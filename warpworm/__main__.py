import sys

from warpworm.cli import main

sys.exit(main())

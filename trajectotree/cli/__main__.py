import sys

from trajectotree.cli import main

sys.exit(main())

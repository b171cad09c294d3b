"""``python -m pwas_hdl ...``: the same as the ``pwas-hdl`` command."""

import sys

from pwas_hdl.cli import main

sys.exit(main())

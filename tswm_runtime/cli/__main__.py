"""``python -m tswm_runtime.cli``: the tswm command."""
import sys

from tswm_runtime.cli import main

sys.exit(main())

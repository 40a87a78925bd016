"""``python -m tswm_runtime.cli``: the tswm command."""
from tswm_runtime.cli import command

command()

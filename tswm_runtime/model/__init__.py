"""The generated model as the runtime sees it: its contract, its integer tables, its parameter rules."""

"""The ``orchestrator`` commands' handlers, a module per group; orchestrator/cli.py parses the
command line and calls them."""

"""canopen's and python-can's log records go where deltoctl sends its own (-v, --log-file),
never to stderr through Python's last resort. Imported by the modules that use the libraries,
not by the descriptor deltoctl reads at start-up."""

import logging

for _name in ("canopen", "can"):
    logging.getLogger(_name).addHandler(logging.NullHandler())

"""The command line: thin typer apps that parse options, open a device, call one verb, render."""

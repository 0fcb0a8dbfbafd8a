"""How results look to a person: text lines, tables, live views and heat maps made from the
data the application layer returns (the JSON documents' data). The CLI prints them; a script
or a notebook may too. Nothing here parses a command line, prompts or exits (no typer or
click), and rich is imported only where a renderable is built."""

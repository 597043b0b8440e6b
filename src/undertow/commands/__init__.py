"""Commands: what each CLI command does, as library functions, one module per CLI module with
the same name (``undertow.cli.mapping`` parses and prints, ``undertow.commands.mapping`` maps).
File paths and settings go in, a result object with the warnings and facts the command prints
comes out; the command line only parses arguments, calls one function and prints its result,
and a Python user calls the same function."""

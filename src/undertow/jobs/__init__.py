"""Jobs: what each command does, as library functions (file paths and settings in, a result
object with the warnings and facts a command prints out). The command line only parses
arguments, calls one job and prints its result; a Python user calls the same job."""

"""Run the CLI as `python -m cloudsim.cli`."""

from cloudsim.cli import main

main()

"""`python -m rbcli` is `rbsim`."""

from rbcli.cli.app import main

main()

"""``python -m kbcli``: the same as the ``kbcli`` command."""

from kbcli.cli import main

if __name__ == "__main__":
    main()

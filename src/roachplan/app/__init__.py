"""The user-facing shells: the `roachplan` command line and the viser browser app."""

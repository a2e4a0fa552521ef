"""The shipped acceptance suite run by ``imubench jig run`` (pytest test modules; they
need the jig plugin's fixtures and are never collected by the project's own tests)."""

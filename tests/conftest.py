"""Session-wide hooks: print the tally of the generated hardening cases (tests/core/test_fuzz)."""


def pytest_terminal_summary(terminalreporter):
    import sys

    mod = sys.modules.get("test_fuzz") or next(
        (m for name, m in sys.modules.items() if name.endswith("test_fuzz")), None
    )
    outcomes = getattr(mod, "OUTCOMES", None)
    if not outcomes:
        return
    total = sum(outcomes.values())
    terminalreporter.write_line(f"hardening cases generated: {total}")
    for key, count in sorted(outcomes.items()):
        terminalreporter.write_line(f"  {count:4d}  {key}")

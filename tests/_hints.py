"""Reading the library's warnings in tests."""

import re


def named_delays(message):
    """The input delays that the dead-time warning of the linear model names:
    the best, and those within a few percent of it."""
    delays = {int(re.search(r"delayed by (\d+) sample\(s\)", message).group(1))}
    others = re.search(r"and by ([\d, or]+) sample\(s\) within", message)
    if others:
        delays |= {int(delay) for delay in re.split(r", | or ", others.group(1))}
    return delays

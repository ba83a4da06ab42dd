"""Reading the library's warnings in tests."""

import re


def named_delays(message):
    """The input delays that the dead-time warning of the linear model names."""
    named = re.search(r"delayed by ([\d, to]+) sample\(s\)", message).group(1)
    if " to " in named:
        first, last = map(int, named.split(" to "))
        return set(range(first, last + 1))
    return {int(delay) for delay in named.split(", ")}

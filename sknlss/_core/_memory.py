"""The memory a fit may use, checked before the fit allocates it."""

import os

try:  # POSIX only
    import resource
except ImportError:  # pragma: no cover - Windows
    resource = None

#: A fit may plan to use at most this share of the memory still available:
#: the rest is left to the data, the interpreter and the other processes.
MEMORY_FRACTION = 0.5


def _meminfo_available():
    """MemAvailable of /proc/meminfo (Linux), else the free physical pages."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def _address_space_left():
    """What the address-space limit (``ulimit -v``) leaves to this process, or None."""
    if resource is None:
        return None
    limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    if limit == resource.RLIM_INFINITY:
        return None
    try:
        with open("/proc/self/statm", encoding="ascii") as statm:
            used = int(statm.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        used = 0
    return max(limit - used, 0)


def available_memory():
    """Bytes this process can still allocate, or None where it cannot be known.

    The system's available memory, capped by the address-space limit of the
    process where one is set.
    """
    known = [size for size in (_meminfo_available(), _address_space_left())
             if size is not None]
    return min(known) if known else None


def format_bytes(size):
    """``size`` bytes in a short human-readable form, e.g. ``"44 GB"``."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if size < 1000 or unit == "PB":
            break
        size /= 1000
    return f"{size:.3g} {unit}"


def check_memory(needed, what, advice=""):
    """A ValueError when ``needed`` bytes exceed :data:`MEMORY_FRACTION` of the
    available memory; ``what`` says what needs them, naming its arguments, and
    ``advice`` what to change."""
    available = available_memory()
    if available is not None and needed > MEMORY_FRACTION * available:
        raise ValueError(
            f"{what} needs about {format_bytes(needed)}, more than "
            f"{MEMORY_FRACTION:.0%} of the {format_bytes(available)} of memory "
            f"available. {advice}".rstrip()
        )

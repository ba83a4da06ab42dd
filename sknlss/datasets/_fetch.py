"""Finding, checking and downloading the benchmark data files.

Every loader describes its data with a :class:`RemoteDataset` and calls
:func:`fetch_file`, which searches the data folders, checks the SHA-256 of the
file it finds and, when no folder holds one, downloads the official archive
into the user cache folder and extracts the data file from it.
"""

import contextlib
import hashlib
import os
import shutil
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import pooch

# Connect and read timeouts (s): a machine without network fails at once on
# the name lookup; one behind a silent firewall gives up after the first.
_TIMEOUT = (10.0, 60.0)


@dataclass(frozen=True)
class RemoteDataset:
    """Where a benchmark's data file is looked for and how it is downloaded.

    Attributes
    ----------
    title : str
        Name of the benchmark, for messages.
    subfolder : str
        Sub-folder of a data folder that holds the files.
    files : dict of str to str
        Accepted file names, in order of preference, with their SHA-256.
    archive_url : str
        Address of the official archive.
    archive_name : str
        File name of the archive.
    archive_sha256 : str or None
        SHA-256 of the archive, when it is known.
    member : str
        Path inside the archive of the file to extract; its base name is a key
        of ``files``.
    source : str
        Where the data come from, for messages.
    """

    title: str
    subfolder: str
    files: dict
    archive_url: str
    archive_name: str
    archive_sha256: str | None
    member: str
    source: str


def cache_home():
    """The user cache folder: ``$XDG_CACHE_HOME/sknlss``, by default ``~/.cache/sknlss``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join("~", ".cache")
    return Path(base).expanduser() / "sknlss"


def data_folders(data_home):
    """The folders searched, in order: ``data_home``, ``$SKNLSS_DATA``, the cache folder."""
    folders = []
    if data_home is not None:
        folders.append(Path(data_home).expanduser())
    if os.environ.get("SKNLSS_DATA"):
        folders.append(Path(os.environ["SKNLSS_DATA"]).expanduser())
    folders.append(cache_home())
    return folders


def candidate_paths(dataset, folder):
    """Paths where ``folder`` may hold the data: its sub-folder first, then itself."""
    for place in (folder / dataset.subfolder, folder):
        for name in dataset.files:
            yield place / name


def file_sha256(path):
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_sha256(dataset, path):
    """Raise ValueError unless ``path`` has the SHA-256 recorded for its name."""
    expected = dataset.files[Path(path).name]
    found = file_sha256(path)
    if found != expected:
        raise ValueError(
            f"{path} is not the official {dataset.title} file: its SHA-256 is "
            f"{found}, expected {expected}. The copy is corrupted or truncated; "
            "replace it with an intact one."
        )


def _downloader():
    return pooch.HTTPDownloader(timeout=_TIMEOUT, progressbar=False)


def _download(dataset, destination):
    """Download the archive, extract the data file and move it to ``destination``.

    The archive is fetched into a temporary folder beside ``destination`` and
    removed afterwards, so that a failed or rejected download leaves nothing
    behind. Raises OSError (network errors are OSErrors), ValueError (a hash
    that does not match) or zipfile.BadZipFile.
    """
    # The folders this call creates, the deepest first: removed again on failure.
    created = [folder for folder in (destination.parent, *destination.parent.parents)
               if not folder.exists()]
    destination.parent.mkdir(parents=True, exist_ok=True)
    try:
        with tempfile.TemporaryDirectory(dir=destination.parent) as tmp:
            known_hash = (None if dataset.archive_sha256 is None
                          else f"sha256:{dataset.archive_sha256}")
            archive = pooch.retrieve(
                dataset.archive_url, known_hash=known_hash, fname=dataset.archive_name,
                path=tmp, downloader=_downloader(),
            )
            with zipfile.ZipFile(archive) as zipped:
                if dataset.member not in zipped.namelist():
                    raise OSError(
                        f"the archive downloaded from {dataset.archive_url} has no "
                        f"member {dataset.member}"
                    )
                extracted = Path(zipped.extract(dataset.member, Path(tmp) / "extracted"))
            check_sha256(dataset, extracted)
            shutil.move(extracted, destination)
    except BaseException:
        for folder in created:
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


def _not_found_message(dataset, folders, reason):
    names = " or ".join(f"'{name}'" for name in dataset.files)
    places = "\n".join(f"  - {folder / dataset.subfolder}/  or  {folder}/"
                       for folder in folders)
    failure = "" if reason is None else f" and could not be downloaded ({reason})"
    return (
        f"The {dataset.title} data were not found{failure}.\n"
        f"Put {names} (from {dataset.source}) in one of the searched folders:\n"
        f"{places}\n"
        "The folders searched are: the data_home argument, then the folder named by "
        "the environment variable SKNLSS_DATA, then the user cache folder "
        "($XDG_CACHE_HOME/sknlss or ~/.cache/sknlss)."
    )


def fetch_file(dataset, data_home, download_if_missing):
    """Path of the checked data file of ``dataset``, downloaded if need be.

    Parameters
    ----------
    dataset : RemoteDataset
        The benchmark.
    data_home : str, path-like or None
        First folder to search.
    download_if_missing : bool
        Whether to download the official archive when no folder has the data.

    Returns
    -------
    path : pathlib.Path
        The data file; its SHA-256 is the recorded one.

    Raises
    ------
    FileNotFoundError
        When no folder has the data and they cannot be downloaded; the message
        names the accepted files, the folders searched and why the download
        failed.
    ValueError
        When the file found does not have the recorded SHA-256.
    """
    folders = data_folders(data_home)
    found = next((path for folder in folders for path in candidate_paths(dataset, folder)
                  if path.is_file()), None)
    if found is not None:
        check_sha256(dataset, found)
        return found
    if not download_if_missing:
        raise FileNotFoundError(_not_found_message(dataset, folders, None))
    destination = cache_home() / dataset.subfolder / PurePosixPath(dataset.member).name
    try:
        _download(dataset, destination)
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise FileNotFoundError(_not_found_message(dataset, folders, exc)) from exc
    return destination

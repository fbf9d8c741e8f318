"""The user's data sets, registered by name in one JSON file: the pipeline's ``dataset``
partitions are the built-in data sets and the names in that file. Registration reads and
checks the whole data file first and registers nothing when anything is wrong."""

import json
import os
from pathlib import Path

from filelock import FileLock

from ..datasets import Dataset
from ..datasets.user import UserDataset

#: Version of the registry file's layout.
REGISTRY_VERSION = 1


class DatasetRegistry:
    """The user's data sets, kept in one JSON file.

    Parameters
    ----------
    path : path-like
        The registry file; it need not exist yet (no data sets).
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path).resolve()

    def _read(self) -> dict[str, dict]:
        if not self.path.is_file():
            return {}
        try:
            content = json.loads(self.path.read_text())
            return dict(content["datasets"])
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            raise ValueError(f"the data-set registry {self.path} is unreadable ({exc}); fix "
                             f"or delete it") from None

    def _write(self, entries: dict[str, dict]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps({"version": REGISTRY_VERSION, "datasets": entries},
                                  indent=2, sort_keys=True) + "\n")
        os.replace(tmp, self.path)

    def _lock(self) -> FileLock:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        return FileLock(str(self.path) + ".lock", timeout=30)

    def names(self) -> list[str]:
        """The registered names, sorted."""
        return sorted(self._read())

    def get(self, name: str) -> UserDataset:
        """The registration of ``name``; an entry written before units existed has none.

        Raises
        ------
        KeyError
            ``name`` is not registered (naming the ones that are).
        ValueError
            The entry breaks a rule made after it was registered (such as the column-name
            rule of `check_column`): in one line naming the
            data set, the rule and how to register it again. Only this entry is refused;
            the others still load.
        """
        entries = self._read()
        if name not in entries:
            raise KeyError(f"no data set {name!r} in {self.path}; registered: {sorted(entries)}")
        entry = entries[name]
        try:
            return UserDataset(**{**entry, "u": tuple(entry["u"]), "y": tuple(entry["y"]),
                                  "test_experiments": tuple(entry["test_experiments"])})
        except ValueError as exc:
            file = entry.get("path", "FILE")
            raise ValueError(f"data set {name!r} registered in {self.path} breaks a rule made "
                             f"since: {exc}. Register it again following the rule (a column "
                             f"renamed in {file} first: python -m pwa_pipeline add-dataset "
                             f"NAME {file} --u … --y … --replace), or remove it "
                             f"(remove-dataset {name})") from None

    def add(self, spec: UserDataset, replace: bool = False,
            one_record: bool = False) -> Dataset:
        """Check ``spec`` by loading its file, then register it.

        Parameters
        ----------
        spec : UserDataset
            The registration.
        replace : bool
            Replace a data set registered under the same name.
        one_record : bool
            Confirm that a file given without an experiment column is one record even if it
            looks like several experiments (`UserDataset.several_experiments`).

        Returns
        -------
        Dataset
            The loaded data set.

        Raises
        ------
        FileNotFoundError, ValueError
            From `UserDataset.load`; a file that looks like several experiments, given
            without an experiment column and ``one_record`` false; or the name is taken and
            ``replace`` is false. Nothing is written then.
        """
        if not one_record and (several := spec.several_experiments()):
            raise ValueError(several)
        data = spec.load()
        with self._lock():
            entries = self._read()
            if spec.name in entries and not replace:
                raise ValueError(f"data set {spec.name!r} is already registered in "
                                 f"{self.path}; remove it first or replace it")
            entries[spec.name] = spec.describe()
            self._write(entries)
        return data

    def remove(self, name: str) -> str:
        """Unregister ``name`` (its file and results stay), even an entry `get`
        refuses; KeyError if unknown.

        Returns
        -------
        str
            The path of its data file.
        """
        with self._lock():
            entries = self._read()
            if name not in entries:
                raise KeyError(f"no data set {name!r} in {self.path}; registered: "
                               f"{sorted(entries)}")
            entry = entries.pop(name)
            self._write(entries)
        return entry["path"]

"""Temporary changes to Blender data that are always undone, in reverse order."""

from __future__ import annotations

from typing import Any


class Overrides:
    """Records attribute changes so that ``restore()`` puts every value back exactly.

    Use as a context manager: the values are restored on leaving the block, also after an
    exception or a cancel (``GeneratorExit``).
    """

    def __init__(self) -> None:
        self._undo: list[tuple[Any, str, Any]] = []

    def set(self, owner: Any, attribute: str, value: Any) -> None:
        """Sets ``owner.attribute = value``, remembering the old value (once per attribute)."""
        if not any(o is owner and a == attribute for o, a, _ in self._undo):
            self._undo.append((owner, attribute, getattr(owner, attribute)))
        setattr(owner, attribute, value)

    def set_if_present(self, owner: Any, attribute: str, value: Any) -> bool:
        """Like ``set`` for settings that only some Blender versions have; False if absent."""
        if not hasattr(owner, attribute):
            return False
        self.set(owner, attribute, value)
        return True

    def restore(self) -> None:
        errors = []
        while self._undo:
            owner, attribute, value = self._undo.pop()
            try:
                setattr(owner, attribute, value)
            except Exception as exc:  # keep restoring the rest, report afterwards
                errors.append(f"{attribute}: {exc}")
        if errors:
            raise RuntimeError("could not restore " + "; ".join(errors))

    def __enter__(self) -> Overrides:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.restore()

"""RowCount: a count that is the number of rows of an array attribute.

The data classes of contactlab (:class:`~contactlab.model.Model`, :class:`~contactlab.hulls.Hull`,
:class:`~contactlab.meshes.TriangleMesh`) keep their items as arrays, one row an item, and name
how many there are (``body_count``, ``vertex_count``, ...). Each such count is one line here,
``body_count = RowCount("body_names")``, followed by its docstring, so that "a count is the length of
its array" has one home and every count says what it counts.
"""

from __future__ import annotations

from typing import Any, overload


class RowCount:
    """A read-only attribute: ``len`` of the attribute named ``of`` of the same object (an int)."""

    def __init__(self, of: str) -> None:
        self.of = of

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @overload
    def __get__(self, instance: None, owner: type | None = None) -> RowCount: ...

    @overload
    def __get__(self, instance: object, owner: type | None = None) -> int: ...

    def __get__(self, instance: object | None, owner: type | None = None) -> RowCount | int:
        if instance is None:  # read on the class: the descriptor itself (documentation tools read it)
            return self
        return len(getattr(instance, self.of))

    def __set__(self, instance: object, value: Any) -> None:
        # as a property without a setter: a count follows its array and is never set
        raise AttributeError(f"{self.name} is the number of rows of {self.of} and cannot be set")

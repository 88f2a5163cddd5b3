"""Kernel calls that skip numba's typing of the arguments once the overload is known.

At every call numba types each argument to choose the compiled overload. For
the named-tuple bundles (``bundles``) that typing runs in Python, some 2.5 µs
a bundle: 7 µs for each call of the force kernel, about 12 µs a step in all,
4 % of a step on a 2 000-sphere pile (docs/performance.md). ``Bound`` lets
numba choose the overload once, by its own dispatch, and then calls that
overload's compiled entry point, which only unboxes the arguments.

The entry point does not check types: an argument of another numba type
(another dtype, number of dimensions or layout) than the one it was chosen
for would be read as the wrong type. The types of the arguments are fixed by
the code that allocates them, not by the data, and the owner chooses again
(``reset``) whenever it reallocates arrays. With ``Bound.check`` = k > 0 (the
test suite sets it) every k-th call compares numba's fingerprints of the
arguments (their types, as numba's dispatcher keys them) with the chosen
ones and raises on a difference; a fingerprint costs about as much as the
typing it replaces, so the check samples, and an array replaced by one of
another type stays replaced until it is found.
"""
from numba._dispatcher import compute_fingerprint
from numba.core.dispatcher import Dispatcher


class Bound:
    """A numba kernel called through the overload numba chose at the first call since ``reset``.

    Parameters
    ----------
    kernel : numba dispatcher (an ``@njit`` function), or a plain function
        (``NUMBA_DISABLE_JIT``), which is then simply called.
    """

    # compare the argument types with the chosen overload's at every check-th call (0: never)
    check = 0

    def __init__(self, kernel):
        self.kernel = kernel
        self._entry = None
        self._types = None
        self._prints = None
        self._calls = 0
        self._dispatch = isinstance(kernel, Dispatcher)

    def reset(self):
        """Choose the overload again at the next call (arrays were reallocated)."""
        self._entry = None
        self._types = None
        self._prints = None

    def __call__(self, *args):
        if self._entry is None:
            return self._choose(args)
        if Bound.check:
            self._calls += 1
            if self._calls % Bound.check == 0:
                self._verify(args)
        return self._entry(*args)

    def _types_of(self, args):
        return tuple(self.kernel.typeof_pyval(a) for a in args)

    def _verify(self, args):
        if tuple(map(compute_fingerprint, args)) == self._prints:
            return
        # fingerprints differ where numba's types may not (a Python int and a numpy int64 are both int64)
        types = self._types_of(args)
        if types != self._types:
            raise TypeError(f"{self.kernel.__name__}: argument types changed since the overload was chosen "
                            f"without a reset: {types} against {self._types}")

    def _choose(self, args):
        # numba's own dispatch: types the arguments, compiles a new overload if none fits
        out = self.kernel(*args)
        if self._dispatch:
            prints = tuple(map(compute_fingerprint, args))
            types = _TYPES.get(prints)
            if types is None:
                # numba's typing of named tuples runs in Python (some 0.3 ms): once per kind of arguments
                types = _TYPES[prints] = self._types_of(args)
            compiled = self.kernel.overloads.get(types)
            # None: numba took an overload of other (convertible) types; keep calling the dispatcher
            if compiled is not None:
                self._entry, self._types, self._prints = compiled.entry_point, types, prints
        return out


# numba types of the arguments by their fingerprints, as numba's dispatcher caches them
_TYPES = {}

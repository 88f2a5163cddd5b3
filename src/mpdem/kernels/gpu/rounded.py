"""GPU twins of the law's functions, every float64 operation explicitly rounded.

The GPU compilers contract a multiply feeding an add into one fused
multiply-add (FMA), rounded once instead of twice; numba-cuda does so even
without ``fastmath`` (the PTX holds ``fma.rn.f64``). The CPU engine's kernels
round every operation, so the two engines would part after a few hundred
steps. A twin is the same source as the CPU's function (``kernels/law.py``,
``kernels/geometry.py``) with each ``a + b``, ``a - b``, ``a * b``, ``a / b``
and ``math.sqrt(a)`` replaced by libdevice's correctly rounded
``dadd_rn``, ``dadd_rn(a, -b)``, ``dmul_rn``, ``ddiv_rn`` and ``dsqrt_rn``,
which the compilers leave as they are. The same operations in the same order
give the same bits (docs/computing.md, "One law, two targets").

Under numba's CUDA simulator (no GPU) libdevice is not there; the operators
are Python's, whose float64 arithmetic rounds every operation as well.
"""
import ast
import inspect
import math
import textwrap

from .. import geometry, law
from .runtime import SIMULATOR, device

if SIMULATOR:
    def _add(a, b):
        return a + b

    def _sub(a, b):
        return a - b

    def _mul(a, b):
        return a * b

    def _div(a, b):
        return a / b

    _sqrt = math.sqrt
else:
    from numba.cuda import libdevice

    @device
    def _add(a, b):
        return libdevice.dadd_rn(a, b)

    @device
    def _sub(a, b):
        # a - b is a + (-b) exactly; libdevice's dsub_rn is not in every numba-cuda
        return libdevice.dadd_rn(a, -b)

    @device
    def _mul(a, b):
        return libdevice.dmul_rn(a, b)

    @device
    def _div(a, b):
        return libdevice.ddiv_rn(a, b)

    @device
    def _sqrt(a):
        return libdevice.dsqrt_rn(a)

OPS = {"_add": _add, "_sub": _sub, "_mul": _mul, "_div": _div, "_sqrt": _sqrt}
_BINARY = {ast.Add: "_add", ast.Sub: "_sub", ast.Mult: "_mul", ast.Div: "_div"}


class _Rounded(ast.NodeTransformer):
    """The source of one function with its float arithmetic as calls of ``OPS``."""

    def visit_FunctionDef(self, node):
        node.decorator_list = []
        self.generic_visit(node)
        return node

    def visit_BinOp(self, node):
        self.generic_visit(node)
        name = _BINARY.get(type(node.op))
        if name is None:
            raise ValueError(f"line {node.lineno}: the operator {type(node.op).__name__} has no rounded twin")
        return ast.copy_location(ast.Call(ast.Name(name, ast.Load()), [node.left, node.right], []), node)

    def visit_AugAssign(self, node):
        self.generic_visit(node)
        name = _BINARY.get(type(node.op))
        if name is None or not isinstance(node.target, ast.Name):
            raise ValueError(f"line {node.lineno}: only name op= value has a rounded twin")
        value = ast.Call(ast.Name(name, ast.Load()), [ast.Name(node.target.id, ast.Load()), node.value], [])
        return ast.copy_location(ast.Assign([node.target], value), node)

    def visit_Call(self, node):
        self.generic_visit(node)
        f = node.func
        if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id == "math":
            if f.attr != "sqrt":
                raise ValueError(f"line {node.lineno}: math.{f.attr} has no rounded twin")
            node.func = ast.Name("_sqrt", ast.Load())
        return node


def rounded_source(fn):
    """The source of the numba function ``fn`` with its arithmetic explicitly rounded (a string)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(fn.py_func)))
    tree = ast.fix_missing_locations(_Rounded().visit(tree))
    return ast.unparse(tree)


def twins(module, names, namespace):
    """GPU device functions of ``module``'s numba functions ``names``, in that order, made in
    ``namespace`` (a dict: a later function calls the earlier twins by name). Returns it."""
    for name in names:
        source = rounded_source(getattr(module, name))
        exec(compile(source, f"<rounded twin of {module.__name__}.{name}>", "exec"), namespace)
        namespace[name] = device(namespace[name])
    return namespace


# every law function, in the order of law.py (one may call those above it)
LAW_FUNCTIONS = ("norm2", "dot", "approach", "spin", "slip", "normal", "tangential", "normal_force",
                 "contact_force", "contact_torque", "floor_force", "plane_contact", "kicks", "drift")

_space = {k: v for k, v in vars(law).items() if not k.startswith("__")}
_space.update(OPS)
_space["math"] = math
twins(geometry, ("min_image",), _space)
twins(law, LAW_FUNCTIONS, _space)

min_image = _space["min_image"]
norm2, dot, approach, spin, slip = (_space[k] for k in ("norm2", "dot", "approach", "spin", "slip"))
normal, tangential, normal_force = _space["normal"], _space["tangential"], _space["normal_force"]
contact_force, contact_torque = _space["contact_force"], _space["contact_torque"]
floor_force, plane_contact = _space["floor_force"], _space["plane_contact"]
kicks, drift = _space["kicks"], _space["drift"]
add, sub, mul, sqrt = _add, _sub, _mul, _sqrt

"""Sparse symmetric block LDL^T factorisation of a matrix with a fixed pattern.

The matrix A (n_nodes b x n_nodes b) is made of b x b node blocks: block (i, j) is
non-zero only for i = j or a pair (i, j) of the node graph given once (a mesh's
edges). ``analyse`` orders the nodes to reduce fill (minimum degree on the node graph,
``minimum_degree``) and computes the elimination tree and the pattern of L (the
symbolic factorisation, a numba kernel too: ``_symbolic``); the numba kernels then
factorise A = L D L^T with unit lower block-triangular L and block-diagonal D (b x b
blocks) for new values on that pattern, and solve with the factors. Algorithms as
described in T. A. Davis, "Direct Methods for Sparse Linear Systems", SIAM 2006: the
elimination tree (section 4.1, Liu's algorithm with path compression), the row patterns
of L as reaches in the tree (section 4.2), the up-looking factorisation row by row
(section 4.7, here on blocks), and the triangular solves (section 3.1); minimum degree
as in section 7.1 (George & Liu 1989), on the explicit elimination graph.

Storage, in the fill-reducing order (``SparsePattern.position[i]``: the position of
node i; ``order`` its inverse):
- the matrix: values (n_blocks + 1, b, b) float64, ``SparsePattern.n_blocks`` =
  n_nodes + n_off blocks. Block k < n_nodes is the diagonal block at position k (the
  full b x b block of node order[k]); block n_nodes + m is the strictly lower block
  (row position r, column position a_col[m] < r) for m in a_ptr[r] .. a_ptr[r + 1] - 1,
  its rows the dofs of the row node. Only the lower blocks are stored: the upper one is
  its transpose. The last block is a sink: ``scatter`` sends an element matrix's
  entries of the upper side there (an element kernel adds every entry of its
  symmetric matrix; the sink's values are never read).
- the factor: l_values (n_factor, b, b), block p the block L[l_row[p], column] of the
  column whose entries are l_ptr[column] .. l_ptr[column + 1] - 1 (rows ascending),
  and d_inv (n_nodes, b, b) the inverses of D's blocks.
- vectors: ``solve`` works in position order, x[b position[i] + a] is dof a of node
  i; ``multiply`` in node order (x[b i + a]). ``SparseLDL`` wraps the kernels for
  node-order vectors.

The numba kernels take ``SparsePattern.arrays`` (a tuple, see ``KernelArrays``).
Import this module only where numba is installed.

Supernodes do not pay at the solid fruit's size (208 nodes, 2149 blocks of L, ~12,300
block updates a factorisation): 108 of its 129 fundamental supernodes are single
columns, and a left-looking supernodal factorisation (Ng & Peyton 1993) took 51-57 us
where this one takes 37-40 us, an up-looking one summing each supernode's updates in a
dense buffer 45 us (README, Benchmarks).
"""
from __future__ import annotations

import dataclasses
import heapq

import numpy as np
from numba import njit, uint64

from gripper_sim.core.pattern_keys import sorted_unique


def minimum_degree(n_nodes: int, pairs: np.ndarray) -> np.ndarray:
    """A fill-reducing elimination order of a graph: minimum degree on the explicit
    elimination graph (eliminating a node joins its neighbours into a clique; ties go
    to the lowest node index).

    Args:
        n_nodes: nodes of the graph.  pairs: (m, 2) int, its edges (either direction,
            repeats and self-loops ignored).

    Returns:
        (n_nodes,) int64, the nodes in elimination order.
    """
    neighbours = [set() for _ in range(n_nodes)]
    for i, j in np.asarray(pairs, dtype=np.int64).reshape(-1, 2).tolist():
        if i != j:
            neighbours[i].add(j)
            neighbours[j].add(i)
    heap = [(len(adj), i) for i, adj in enumerate(neighbours)]
    heapq.heapify(heap)
    eliminated = np.zeros(n_nodes, bool)
    order = []
    while heap:
        degree, node = heapq.heappop(heap)
        if eliminated[node] or degree != len(neighbours[node]):
            continue  # an outdated entry: the node is in the heap again
        eliminated[node] = True
        order.append(node)
        clique = neighbours[node]
        for other in clique:
            adj = neighbours[other]
            adj.discard(node)
            adj.update(clique)
            adj.discard(other)
            heapq.heappush(heap, (len(adj), other))
        neighbours[node] = set()
    return np.asarray(order, dtype=np.int64)


@dataclasses.dataclass(frozen=True)
class SparsePattern:
    """The symbolic factorisation of a block-sparse symmetric matrix (see the module doc).

    Attributes:
        n_nodes, block: block rows and the block size b.
        order: (n_nodes,) int64, the node at each position.  position: its inverse.
        a_ptr: (n_nodes + 1,), a_col: (n_off,) int64: the strictly lower blocks of A by
            rows, in positions.
        parent: (n_nodes,) int64, the elimination tree (-1: a root).
        l_ptr: (n_nodes + 1,), l_row: (n_factor,) int64: L's strictly lower blocks by
            columns (rows ascending).
        r_ptr: (n_nodes + 1,), r_col, r_index: (n_factor,) int64: the same blocks by rows
            (columns ascending): column and index into l_values.
    """

    n_nodes: int
    block: int
    order: np.ndarray
    position: np.ndarray
    a_ptr: np.ndarray
    a_col: np.ndarray
    parent: np.ndarray
    l_ptr: np.ndarray
    l_row: np.ndarray
    r_ptr: np.ndarray
    r_col: np.ndarray
    r_index: np.ndarray

    @property
    def n_blocks(self) -> int:
        """Stored blocks of A (diagonal and strictly lower), without the sink."""
        return self.n_nodes + len(self.a_col)

    @property
    def n_factor(self) -> int:
        """Strictly lower blocks of L (A's and the fill)."""
        return len(self.l_row)

    @property
    def sink(self) -> int:
        """Index of the sink block of a values array."""
        return self.n_blocks

    @property
    def arrays(self) -> tuple:
        """The kernels' view (``KernelArrays``)."""
        return (self.order, self.position, self.a_ptr, self.a_col, self.l_ptr, self.l_row,
                self.r_ptr, self.r_col, self.r_index)

    def new_values(self) -> np.ndarray:
        """A zero values array (n_blocks + 1, b, b) for A."""
        return np.zeros((self.n_blocks + 1, self.block, self.block))

    def block_index(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where node blocks (rows[k], cols[k]) of A are stored.

        Returns:
            (index (k,) int64 into the values' blocks, transposed (k,) bool: the stored
            block is the transpose of block (row, col), which is on the upper side).
            Raises ValueError for a block outside the pattern.
        """
        pr = self.position[np.asarray(rows, dtype=np.int64)]
        pc = self.position[np.asarray(cols, dtype=np.int64)]
        transposed = pr < pc
        hi, lo = np.where(transposed, pc, pr), np.where(transposed, pr, pc)
        index = hi.copy()  # the diagonal blocks
        off = hi != lo
        if np.any(off):
            # the strictly lower blocks by rows, columns ascending in each row
            keys = self._lower_keys()
            wanted = hi[off] * self.n_nodes + lo[off]
            found = np.searchsorted(keys, wanted)
            if np.any(found >= len(keys)) or np.any(keys[np.minimum(found, len(keys) - 1)]
                                                    != wanted):
                raise ValueError('a block outside the pattern')
            index[off] = self.n_nodes + found
        return index, transposed

    def _lower_keys(self) -> np.ndarray:
        rows = np.repeat(np.arange(self.n_nodes), np.diff(self.a_ptr))
        return rows * self.n_nodes + self.a_col

    def scatter(self, element_nodes: np.ndarray) -> np.ndarray:
        """Positions of element matrices' entries in a flat values array.

        Args:
            element_nodes: (n_elem, m) int, the nodes of each element; its matrix is
                (m b x m b), dofs [node 0 dof 0 .. b-1, node 1 ...].

        Returns:
            (n_elem, (m b)^2) int64: entry (r, s) at r m b + s, the flat index into
            ``values.reshape(-1)``; entries of the upper side go to the sink block.
        """
        nodes = np.asarray(element_nodes, dtype=np.int64)
        n_elem, m = nodes.shape
        b = self.block
        size = m * b
        r = np.repeat(np.arange(size), size)
        s = np.tile(np.arange(size), size)
        rows, cols = nodes[:, r // b], nodes[:, s // b]
        index, transposed = self.block_index(rows.ravel(), cols.ravel())
        index = index.reshape(n_elem, size * size)
        transposed = transposed.reshape(n_elem, size * size)
        flat = (index * b + (r % b)[None, :]) * b + (s % b)[None, :]
        # upper-side entries in turn over the sink's b^2 values: fewer adds in a row to
        # one address (each waits for the one before)
        sink = self.sink * b * b + np.arange(size * size) % (b * b)
        return np.where(transposed, sink[None, :], flat).astype(np.int64)


#: the tuple ``SparsePattern.arrays`` the kernels take, by name
KernelArrays = ('order', 'position', 'a_ptr', 'a_col', 'l_ptr', 'l_row', 'r_ptr', 'r_col',
                'r_index')


def analyse(n_nodes: int, pairs: np.ndarray, block: int,
            order: np.ndarray | None = None) -> SparsePattern:
    """The symbolic factorisation of a matrix of b x b node blocks.

    Args:
        n_nodes: block rows.  pairs: (m, 2) int, the off-diagonal node blocks (i, j)
            that may be non-zero (either direction: the pattern is symmetric).
        block: b, dofs per node (>= 1).
        order: (n_nodes,) nodes in elimination order; default ``minimum_degree``.
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if block < 1 or (pairs.size and (pairs.min() < 0 or pairs.max() >= n_nodes)):
        raise ValueError('pairs must name nodes 0 .. n_nodes - 1 and block be >= 1')
    if order is None:
        order = minimum_degree(n_nodes, pairs)
    order = np.asarray(order, dtype=np.int64)
    if not np.array_equal(np.sort(order), np.arange(n_nodes)):
        raise ValueError('order must be a permutation of the nodes')
    position = np.empty(n_nodes, np.int64)
    position[order] = np.arange(n_nodes)
    p = position[pairs]
    p = p[p[:, 0] != p[:, 1]]
    hi, lo = p.max(axis=1), p.min(axis=1)
    keys = sorted_unique(hi * n_nodes + lo)
    a_rows, a_col = keys // n_nodes, keys % n_nodes
    a_ptr = np.searchsorted(a_rows, np.arange(n_nodes + 1)).astype(np.int64)
    a_col = a_col.astype(np.int64)
    parent, l_ptr, l_row, r_ptr, r_col, r_index = _symbolic(n_nodes, a_ptr, a_col)
    return SparsePattern(n_nodes, int(block), order, position, a_ptr, a_col,
                         parent, l_ptr, l_row, r_ptr, r_col, r_index)


# ---------------------------------------------------------------------- numba kernels
@njit(cache=True)
def _symbolic(n, a_ptr, a_col):
    """The symbolic factorisation of the strictly lower blocks of A by rows, in
    positions (``a_ptr`` (n + 1,), ``a_col``, columns ascending in each row): the
    elimination tree (Liu's algorithm with path compression, Davis 2006 section 4.1),
    the rows of L as the reaches of A's rows in it (section 4.2, each sorted), and L's
    blocks by columns, rows ascending. Returns (parent, l_ptr, l_row, r_ptr, r_col,
    r_index) int64, as ``SparsePattern`` holds them."""
    parent = np.full(n, -1, np.int64)
    ancestor = np.full(n, -1, np.int64)  # path-compressed ancestors
    for k in range(n):
        for p in range(a_ptr[k], a_ptr[k + 1]):
            i = a_col[p]
            while i != -1 and i < k:
                following = ancestor[i]
                ancestor[i] = k
                if following == -1:
                    parent[i] = k
                i = following
    mark = np.full(n, -1, np.int64)
    r_ptr = np.zeros(n + 1, np.int64)
    for k in range(n):  # each row's size: its reach in the tree
        mark[k] = k
        size = 0
        for p in range(a_ptr[k], a_ptr[k + 1]):
            i = a_col[p]
            while mark[i] != k:
                size += 1
                mark[i] = k
                i = parent[i]
        r_ptr[k + 1] = r_ptr[k] + size
    r_col = np.empty(r_ptr[n], np.int64)
    mark[:] = -1
    for k in range(n):
        mark[k] = k
        top = r_ptr[k]
        for p in range(a_ptr[k], a_ptr[k + 1]):
            i = a_col[p]
            while mark[i] != k:
                r_col[top] = i
                top += 1
                mark[i] = k
                i = parent[i]
        r_col[r_ptr[k]:r_ptr[k + 1]].sort()
    l_ptr = np.zeros(n + 1, np.int64)
    for e in range(r_ptr[n]):
        l_ptr[r_col[e] + 1] += 1
    for j in range(n):
        l_ptr[j + 1] += l_ptr[j]
    filled = l_ptr[:n].copy()
    l_row = np.empty(r_ptr[n], np.int64)
    r_index = np.empty(r_ptr[n], np.int64)
    for k in range(n):  # rows ascending: each column's rows come ascending
        for e in range(r_ptr[k], r_ptr[k + 1]):
            j = r_col[e]
            l_row[filled[j]] = k
            r_index[e] = filled[j]
            filled[j] += 1
    return parent, l_ptr, l_row, r_ptr, r_col, r_index


@njit(cache=True)
def _invert_block(d, out):
    """out = d^-1 for a small symmetric block d (b, b). Returns 0 if d is positive
    definite, 1 if it is not (but regular), -1 if it is singular or not finite."""
    b = d.shape[0]
    if b == 1:
        if d[0, 0] == 0.0 or not np.isfinite(d[0, 0]):
            return -1
        out[0, 0] = 1.0 / d[0, 0]
        return 0 if d[0, 0] > 0.0 else 1
    if b == 2:
        d00, d01, d11 = d[0, 0], d[1, 0], d[1, 1]
        det = d00 * d11 - d01 * d01
        if det == 0.0 or not np.isfinite(det):
            return -1
        out[0, 0] = d11 / det
        out[0, 1] = -d01 / det
        out[1, 0] = -d01 / det
        out[1, 1] = d00 / det
        return 0 if det > 0.0 and d00 > 0.0 else 1
    # Gauss-Jordan with partial pivoting; positive definiteness by Cholesky's pivots
    work = np.empty((b, 2 * b))
    definite = True
    chol = d.copy()
    for k in range(b):
        pivot = chol[k, k]
        for m in range(k):
            pivot -= chol[k, m] * chol[k, m]
        if not pivot > 0.0:
            definite = False
            break
        chol[k, k] = np.sqrt(pivot)
        for r in range(k + 1, b):
            acc = chol[r, k]
            for m in range(k):
                acc -= chol[r, m] * chol[k, m]
            chol[r, k] = acc / chol[k, k]
    for r in range(b):
        for c in range(b):
            work[r, c] = d[r, c]
            work[r, b + c] = 1.0 if r == c else 0.0
    for k in range(b):
        best = k
        for r in range(k + 1, b):
            if abs(work[r, k]) > abs(work[best, k]):
                best = r
        if work[best, k] == 0.0 or not np.isfinite(work[best, k]):
            return -1
        if best != k:
            for c in range(2 * b):
                work[k, c], work[best, c] = work[best, c], work[k, c]
        scale = 1.0 / work[k, k]
        for c in range(2 * b):
            work[k, c] *= scale
        for r in range(b):
            if r != k and work[r, k] != 0.0:
                f = work[r, k]
                for c in range(2 * b):
                    work[r, c] -= f * work[k, c]
    for r in range(b):
        for c in range(b):
            out[r, c] = work[r, b + c]
        for c in range(b):
            if not np.isfinite(out[r, c]):
                return -1
    return 0 if definite else 1


@njit(cache=True)
def factor(arrays, values, l_values, d_inv):
    """A = L D L^T (up-looking, block by block; see the module doc for the storage).

    Args:
        arrays: ``SparsePattern.arrays``.
        values: (n_blocks + 1, b, b) A's blocks (read only).
        l_values: (n_factor, b, b), d_inv: (n_nodes, b, b): the factors (written).

    Returns:
        the number of pivot blocks that are not positive definite (0: A is positive
        definite; otherwise the factors are valid but A is indefinite, A's inertia
        being D's), or -1 - k when the pivot block at position k is singular or not
        finite (the factors are then unusable).
    """
    if d_inv.shape[1] == 2:
        return _factor_2(arrays, values, l_values, d_inv)
    _order, _position, a_ptr, a_col, l_ptr, l_row, r_ptr, r_col, r_index = arrays
    n = d_inv.shape[0]
    b = d_inv.shape[1]
    y = np.zeros((n, b, b))  # row k of L D, being formed (zero outside its pattern)
    w = np.empty((b, b))
    d = np.empty((b, b))
    indefinite = 0
    for k in range(n):
        for m in range(a_ptr[k], a_ptr[k + 1]):
            y[a_col[m]] = values[n + m]
        for r in range(b):
            for c in range(b):
                d[r, c] = values[k, r, c]
        for t in range(r_ptr[k], r_ptr[k + 1]):
            i = r_col[t]
            here = r_index[t]
            for r in range(b):
                for c in range(b):
                    w[r, c] = y[i, r, c]
                    y[i, r, c] = 0.0
            # the rows j < k of column i take w L[j, i]^T off y[j]
            for p in range(l_ptr[i], here):
                j = l_row[p]
                for r in range(b):
                    for c in range(b):
                        acc = 0.0
                        for s in range(b):
                            acc += w[r, s] * l_values[p, c, s]
                        y[j, r, c] -= acc
            # L[k, i] = w D_i^-1 and D_k -= w L[k, i]^T
            for r in range(b):
                for c in range(b):
                    acc = 0.0
                    for s in range(b):
                        acc += w[r, s] * d_inv[i, s, c]
                    l_values[here, r, c] = acc
            for r in range(b):
                for c in range(b):
                    acc = 0.0
                    for s in range(b):
                        acc += w[r, s] * l_values[here, c, s]
                    d[r, c] -= acc
        status = _invert_block(d, d_inv[k])
        if status < 0:
            return -1 - k
        indefinite += status
    return indefinite


@njit(cache=True)
def _factor_2(arrays, values, l_values, d_inv):
    """``factor`` for 2 x 2 blocks, written out (four independent sums per block) on flat
    arrays with unsigned indices (no negative-index wraparound in the inner loops)."""
    _order, _position, a_ptr, a_col, l_ptr, l_row, r_ptr, r_col, r_index = arrays
    n = d_inv.shape[0]
    y = np.zeros(4 * n)  # row k of L D by columns, 4 values each
    lv = l_values.reshape(l_values.size)
    va = values.reshape(values.size)
    dv = d_inv.reshape(d_inv.size)
    indefinite = 0
    for k in range(n):
        for m in range(a_ptr[k], a_ptr[k + 1]):
            j = uint64(4 * a_col[m])
            a = uint64(4 * (n + m))
            y[j] = va[a]
            y[j + 1] = va[a + 1]
            y[j + 2] = va[a + 2]
            y[j + 3] = va[a + 3]
        a = uint64(4 * k)
        d00 = va[a]
        d01 = va[a + 1]
        d11 = va[a + 3]
        for t in range(r_ptr[k], r_ptr[k + 1]):
            column = r_col[t]
            here = r_index[t]
            i = uint64(4 * column)
            w00, w01, w10, w11 = y[i], y[i + 1], y[i + 2], y[i + 3]
            y[i] = 0.0
            y[i + 1] = 0.0
            y[i + 2] = 0.0
            y[i + 3] = 0.0
            for p in range(l_ptr[column], here):
                j = uint64(4 * l_row[p])
                q = uint64(4 * p)
                l00, l01, l10, l11 = lv[q], lv[q + 1], lv[q + 2], lv[q + 3]
                y[j] -= w00 * l00 + w01 * l01
                y[j + 1] -= w00 * l10 + w01 * l11
                y[j + 2] -= w10 * l00 + w11 * l01
                y[j + 3] -= w10 * l10 + w11 * l11
            i00, i01, i10, i11 = dv[i], dv[i + 1], dv[i + 2], dv[i + 3]
            l00 = w00 * i00 + w01 * i10
            l01 = w00 * i01 + w01 * i11
            l10 = w10 * i00 + w11 * i10
            l11 = w10 * i01 + w11 * i11
            q = uint64(4 * here)
            lv[q] = l00
            lv[q + 1] = l01
            lv[q + 2] = l10
            lv[q + 3] = l11
            d00 -= w00 * l00 + w01 * l01
            d01 -= w00 * l10 + w01 * l11
            d11 -= w10 * l10 + w11 * l11
        det = d00 * d11 - d01 * d01
        if det == 0.0 or not np.isfinite(det):
            return -1 - k
        a = uint64(4 * k)
        dv[a] = d11 / det
        dv[a + 1] = -d01 / det
        dv[a + 2] = -d01 / det
        dv[a + 3] = d00 / det
        if not (det > 0.0 and d00 > 0.0):
            indefinite += 1
    return indefinite


@njit(cache=True)
def solve(arrays, l_values, d_inv, x):
    """x <- (L D L^T)^-1 x in place, x (n_nodes b,) in position order (after ``factor``)."""
    l_ptr, l_row = arrays[4], arrays[5]
    n = d_inv.shape[0]
    b = d_inv.shape[1]
    if b == 2:
        _solve_2(l_ptr, l_row, l_values.reshape(l_values.size), d_inv.reshape(d_inv.size), x)
        return
    t = np.empty(b)
    for i in range(n):  # L z = x, by columns
        for p in range(l_ptr[i], l_ptr[i + 1]):
            _subtract_product(l_values[p], False, x, b * i, b * l_row[p])
    for i in range(n):  # D y = z
        for r in range(b):
            acc = 0.0
            for s in range(b):
                acc += d_inv[i, r, s] * x[b * i + s]
            t[r] = acc
        for r in range(b):
            x[b * i + r] = t[r]
    for i in range(n - 1, -1, -1):  # L^T x = y, by columns of L (rows of L^T)
        for p in range(l_ptr[i], l_ptr[i + 1]):
            _subtract_product(l_values[p], True, x, b * l_row[p], b * i)


@njit(cache=True)
def _subtract_product(block, transposed, x, source, target):
    """x[target:target + b] -= B x[source:source + b], B = block (b, b) or its transpose."""
    b = block.shape[0]
    for r in range(b):
        acc = 0.0
        for s in range(b):
            acc += (block[s, r] if transposed else block[r, s]) * x[source + s]
        x[target + r] -= acc


@njit(cache=True)
def _solve_2(l_ptr, l_row, lv, dv, x):
    """``solve`` for 2 x 2 blocks (lv (4 n_factor,), dv (4 n_nodes,) row-major blocks;
    unsigned indices as ``_factor_2``)."""
    n = dv.shape[0] // 4
    for i in range(n):
        x0, x1 = x[2 * i], x[2 * i + 1]
        for p in range(l_ptr[i], l_ptr[i + 1]):
            j = uint64(2 * l_row[p])
            q = uint64(4 * p)
            x[j] -= lv[q] * x0 + lv[q + 1] * x1
            x[j + 1] -= lv[q + 2] * x0 + lv[q + 3] * x1
    for i in range(n):
        x0, x1 = x[2 * i], x[2 * i + 1]
        a = uint64(4 * i)
        x[2 * i] = dv[a] * x0 + dv[a + 1] * x1
        x[2 * i + 1] = dv[a + 2] * x0 + dv[a + 3] * x1
    for i in range(n - 1, -1, -1):
        s0, s1 = x[2 * i], x[2 * i + 1]
        for p in range(l_ptr[i], l_ptr[i + 1]):
            j = uint64(2 * l_row[p])
            q = uint64(4 * p)
            x0, x1 = x[j], x[j + 1]
            s0 -= lv[q] * x0 + lv[q + 2] * x1
            s1 -= lv[q + 1] * x0 + lv[q + 3] * x1
        x[2 * i] = s0
        x[2 * i + 1] = s1


@njit(cache=True)
def multiply(arrays, values, x, out):
    """out = A x for node-order vectors x, out (n_nodes b,) (A's stored blocks)."""
    order, _position, a_ptr, a_col = arrays[0], arrays[1], arrays[2], arrays[3]
    n = order.shape[0]
    b = values.shape[1]
    out[:] = 0.0
    for k in range(n):
        i = order[k]
        for r in range(b):
            acc = 0.0
            for s in range(b):
                acc += values[k, r, s] * x[b * i + s]
            out[b * i + r] += acc
        for m in range(a_ptr[k], a_ptr[k + 1]):
            j = order[a_col[m]]
            blk = values[n + m]
            for r in range(b):
                acc_row = 0.0
                for s in range(b):
                    acc_row += blk[r, s] * x[b * j + s]
                    out[b * j + s] += blk[r, s] * x[b * i + r]
                out[b * i + r] += acc_row


class SparseLDL:
    """Factorise and solve for one ``SparsePattern`` with node-order vectors (numpy glue
    around the kernels, for callers outside numba).

    Example::

        pattern = analyse(n_nodes, mesh_edges, block=2)
        values = pattern.new_values()          # fill via pattern.scatter(...)
        ldl = SparseLDL(pattern)
        if ldl.factorise(values) < 0: ...       # singular
        x = ldl.solve(rhs)                      # (n_nodes b,) or (n_nodes b, k)
    """

    def __init__(self, pattern: SparsePattern):
        self.pattern = pattern
        b = pattern.block
        self.l_values = np.zeros((pattern.n_factor, b, b))
        self.d_inv = np.zeros((pattern.n_nodes, b, b))
        self._dof_order = (b * pattern.order[:, None] + np.arange(b)[None, :]).ravel()

    def factorise(self, values: np.ndarray) -> int:
        """``factor`` of values (n_blocks + 1, b, b): 0 positive definite, > 0 the count
        of indefinite pivot blocks, < 0 singular."""
        return int(factor(self.pattern.arrays, np.ascontiguousarray(values, dtype=float),
                          self.l_values, self.d_inv))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A^-1 rhs for rhs (n_nodes b,) or (n_nodes b, k) in node order."""
        rhs = np.asarray(rhs, dtype=float)
        columns = rhs.reshape(rhs.shape[0], -1)
        out = np.empty_like(columns)
        for c in range(columns.shape[1]):
            x = np.ascontiguousarray(columns[self._dof_order, c])
            solve(self.pattern.arrays, self.l_values, self.d_inv, x)
            out[self._dof_order, c] = x
        return out.reshape(rhs.shape)


@njit(cache=True)
def ldl_solve_3(l_ptr, l_row, l_values, d_inv, x):
    """x <- (L D L^T)^-1 x in place for 3 x 3 node blocks: ``solve`` written
    out for b = 3 (three independent sums per block; about six times faster than its
    loop over a run-time block size).

    Args:
        l_ptr: (n_nodes + 1,), l_row: (n_factor,) the factor's block columns
            (``SparsePattern``).  l_values: (n_factor, 9) L's blocks,
            row-major.  d_inv: (n_nodes, 9) D's inverse blocks, row-major.
        x: (3 n_nodes,) in position order.
    """
    n = d_inv.shape[0]
    for i in range(n):  # L z = x, by columns
        x0, x1, x2 = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        for p in range(l_ptr[i], l_ptr[i + 1]):
            j = 3 * l_row[p]
            x[j] -= l_values[p, 0] * x0 + l_values[p, 1] * x1 + l_values[p, 2] * x2
            x[j + 1] -= l_values[p, 3] * x0 + l_values[p, 4] * x1 + l_values[p, 5] * x2
            x[j + 2] -= l_values[p, 6] * x0 + l_values[p, 7] * x1 + l_values[p, 8] * x2
    for i in range(n):  # D y = z
        x0, x1, x2 = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        x[3 * i] = d_inv[i, 0] * x0 + d_inv[i, 1] * x1 + d_inv[i, 2] * x2
        x[3 * i + 1] = d_inv[i, 3] * x0 + d_inv[i, 4] * x1 + d_inv[i, 5] * x2
        x[3 * i + 2] = d_inv[i, 6] * x0 + d_inv[i, 7] * x1 + d_inv[i, 8] * x2
    for i in range(n - 1, -1, -1):  # L^T x = y, by columns of L (rows of L^T)
        s0, s1, s2 = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        for p in range(l_ptr[i], l_ptr[i + 1]):
            j = 3 * l_row[p]
            x0, x1, x2 = x[j], x[j + 1], x[j + 2]
            s0 -= l_values[p, 0] * x0 + l_values[p, 3] * x1 + l_values[p, 6] * x2
            s1 -= l_values[p, 1] * x0 + l_values[p, 4] * x1 + l_values[p, 7] * x2
            s2 -= l_values[p, 2] * x0 + l_values[p, 5] * x1 + l_values[p, 8] * x2
        x[3 * i] = s0
        x[3 * i + 1] = s1
        x[3 * i + 2] = s2


@njit(cache=True)
def ldl_factor_3(arrays, values, l_values, d_inv):
    """A = L D L^T for 3 x 3 node blocks: ``factor`` written out for b = 3
    (the same up-looking algorithm, storage and return value; about three times
    faster than its loops over a run-time block size).

    Args:
        arrays: ``SparsePattern.arrays``.
        values: (n_blocks + 1, 9) A's blocks, row-major (read only).
        l_values: (n_factor, 9), d_inv: (n_nodes, 9): the factors, row-major (written).

    Returns:
        the number of pivot blocks that are not positive definite, or -1 - k when the
        pivot block at position k is singular or not finite.
    """
    _order, _position, a_ptr, a_col, l_ptr, l_row, r_ptr, r_col, r_index = arrays
    n = d_inv.shape[0]
    y = np.zeros((n, 9))  # row k of L D, being formed (zero outside its pattern)
    indefinite = 0
    for k in range(n):
        for m in range(a_ptr[k], a_ptr[k + 1]):
            for e in range(9):
                y[a_col[m], e] = values[n + m, e]
        d00, d01, d02 = values[k, 0], values[k, 1], values[k, 2]
        d11, d12, d22 = values[k, 4], values[k, 5], values[k, 8]
        for t in range(r_ptr[k], r_ptr[k + 1]):
            i = r_col[t]
            here = r_index[t]
            w00, w01, w02 = y[i, 0], y[i, 1], y[i, 2]
            w10, w11, w12 = y[i, 3], y[i, 4], y[i, 5]
            w20, w21, w22 = y[i, 6], y[i, 7], y[i, 8]
            for e in range(9):
                y[i, e] = 0.0
            # the rows j < k of column i take w L[j, i]^T off y[j]
            for p in range(l_ptr[i], here):
                j = l_row[p]
                for c in range(3):
                    l0, l1, l2 = l_values[p, 3 * c], l_values[p, 3 * c + 1], l_values[p, 3 * c + 2]
                    y[j, c] -= w00 * l0 + w01 * l1 + w02 * l2
                    y[j, 3 + c] -= w10 * l0 + w11 * l1 + w12 * l2
                    y[j, 6 + c] -= w20 * l0 + w21 * l1 + w22 * l2
            # L[k, i] = w D_i^-1 and D_k -= w L[k, i]^T
            for c in range(3):
                i0, i1, i2 = d_inv[i, c], d_inv[i, 3 + c], d_inv[i, 6 + c]
                l_values[here, c] = w00 * i0 + w01 * i1 + w02 * i2
                l_values[here, 3 + c] = w10 * i0 + w11 * i1 + w12 * i2
                l_values[here, 6 + c] = w20 * i0 + w21 * i1 + w22 * i2
            l00, l01, l02 = l_values[here, 0], l_values[here, 1], l_values[here, 2]
            l10, l11, l12 = l_values[here, 3], l_values[here, 4], l_values[here, 5]
            l20, l21, l22 = l_values[here, 6], l_values[here, 7], l_values[here, 8]
            d00 -= w00 * l00 + w01 * l01 + w02 * l02
            d01 -= w00 * l10 + w01 * l11 + w02 * l12
            d02 -= w00 * l20 + w01 * l21 + w02 * l22
            d11 -= w10 * l10 + w11 * l11 + w12 * l12
            d12 -= w10 * l20 + w11 * l21 + w12 * l22
            d22 -= w20 * l20 + w21 * l21 + w22 * l22
        # D_k^-1 by cofactors (D_k symmetric)
        c00 = d11 * d22 - d12 * d12
        c01 = d02 * d12 - d01 * d22
        c02 = d01 * d12 - d02 * d11
        det = d00 * c00 + d01 * c01 + d02 * c02
        if det == 0.0 or not np.isfinite(det):
            return -1 - k
        c11 = d00 * d22 - d02 * d02
        c12 = d01 * d02 - d00 * d12
        c22 = d00 * d11 - d01 * d01
        d_inv[k, 0] = c00 / det
        d_inv[k, 1] = c01 / det
        d_inv[k, 2] = c02 / det
        d_inv[k, 3] = c01 / det
        d_inv[k, 4] = c11 / det
        d_inv[k, 5] = c12 / det
        d_inv[k, 6] = c02 / det
        d_inv[k, 7] = c12 / det
        d_inv[k, 8] = c22 / det
        if not (d00 > 0.0 and c22 > 0.0 and det > 0.0):  # leading minors (Sylvester)
            indefinite += 1
    return indefinite

"""Worker process for the xanfis peer (run by ``peers.XanfisPeer``, never imported by the package).

xanfis 1.1.0 pins ``numpy<=1.26.0`` (and so does its dependency mealpy), while this project runs on
numpy 2, so xanfis lives in its own virtualenv (``.venv-xanfis``, made by ``make venv``) and this
script runs there. It imports nothing from haptic_anfis. Protocol: length-prefixed pickle frames on
stdin/stdout, one request -> one reply; replies are ``('ok', value)`` or ``('error', message)``.
Timings are taken here, inside the process that runs xanfis, so they contain no pipe overhead.

Requests: ('fit', X, Y, params) -> seconds; ('predict', X) -> (n, 3) array;
('time_single', Q, repeats) -> per-call seconds; ('throughput', X, min_seconds) -> evaluations/s;
('curves',) -> {'train': [...], 'valid': [...]} loss per epoch if xanfis kept them; ('quit',).
"""
import os
import pickle
import struct
import sys
import time

import numpy as np

os.environ.setdefault('OMP_NUM_THREADS', '1')   # before torch loads: one math thread
try:  # installed in the xanfis virtualenv only (the package imports this file for the wire format)
    import torch
    from xanfis import AnfisRegressor
except ImportError:
    torch = AnfisRegressor = None


def _read(stream):
    head = stream.read(8)
    if len(head) < 8:
        return None
    (n,) = struct.unpack('<Q', head)
    return _unpack(pickle.loads(stream.read(n)))


def _write(stream, obj):
    data = pickle.dumps(_pack(obj), protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(struct.pack('<Q', len(data)) + data)
    stream.flush()


def _pack(obj):
    """numpy arrays -> ('__f64__', shape, bytes): a pickled array names numpy's private modules,
    which differ between numpy 1 (xanfis' environment) and numpy 2 (ours)."""
    if isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj, dtype=np.float64)
        return ('__f64__', a.shape, a.tobytes())
    if isinstance(obj, (list, tuple)):
        return type(obj)(_pack(v) for v in obj)
    if isinstance(obj, dict):
        return {k: _pack(v) for k, v in obj.items()}
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _unpack(obj):
    if isinstance(obj, tuple) and len(obj) == 3 and obj[0] == '__f64__':
        return np.frombuffer(obj[2], dtype=np.float64).reshape(obj[1]).copy()
    if isinstance(obj, (list, tuple)):
        return type(obj)(_unpack(v) for v in obj)
    if isinstance(obj, dict):
        return {k: _unpack(v) for k, v in obj.items()}
    return obj


def main():
    fin, fout = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # anything xanfis prints must not corrupt the frames
    torch.set_num_threads(1)

    state = {}
    while True:
        req = _read(fin)
        if req is None or req[0] == 'quit':
            return 0
        try:
            op = req[0]
            if op == 'fit':
                _, X, Y, params = req
                mu, sd = X.mean(0), X.std(0)
                sd[sd == 0] = 1.0
                ymu, ysd = Y.mean(0), Y.std(0)
                ysd[ysd == 0] = 1.0
                t0 = time.perf_counter()
                model = AnfisRegressor(**params)
                model.fit((X - mu) / sd, (Y - ymu) / ysd)
                seconds = time.perf_counter() - t0
                state.update(model=model, mu=mu, sd=sd, ymu=ymu, ysd=ysd)
                _write(fout, ('ok', seconds))
            elif op == 'predict':
                _write(fout, ('ok', _predict(state, req[1])))
            elif op == 'time_single':
                _, Q, repeats = req
                out = np.empty(repeats)
                rows = [Q[i:i + 1] for i in range(len(Q))]
                clock = time.perf_counter
                for k in range(repeats):
                    q = rows[k % len(rows)]
                    t0 = clock()
                    _predict(state, q)
                    out[k] = clock() - t0
                _write(fout, ('ok', out))
            elif op == 'throughput':
                _, X, min_seconds = req
                _predict(state, X[:10])
                n, t0 = 0, time.perf_counter()
                while True:
                    _predict(state, X)
                    n += 1
                    dt = time.perf_counter() - t0
                    if dt >= min_seconds:
                        break
                _write(fout, ('ok', n * len(X) / dt))
            elif op == 'curves':
                lc = getattr(state.get('model'), 'loss_train', None)
                _write(fout, ('ok', {'train': [float(v) for v in lc]} if lc else {}))
            else:
                _write(fout, ('error', f'unknown request {op!r}'))
        except Exception as exc:  # report, keep serving
            _write(fout, ('error', f'{type(exc).__name__}: {exc}'))


def _predict(state, X):
    if 'model' not in state:
        raise RuntimeError('predict before fit')
    Z = (X - state['mu']) / state['sd']
    P = state['model'].predict(Z)
    P = P.reshape(len(X), -1)
    return P * state['ysd'] + state['ymu']


if __name__ == '__main__':
    sys.exit(main())

"""``haptic-anfis evaluate MODEL DATASET.csv``: errors of a model file on a dataset."""
from __future__ import annotations

import argparse

import numpy as np

from ..anfis import ForceModel, rmse
from ..tissue.dataset import OUTPUT_NAMES, load_dataset

NAME = 'evaluate'


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('model', help='model file (JSON) written by "haptic-anfis train"')
    p.add_argument('dataset', help='force dataset CSV')


def run(args: argparse.Namespace) -> int:
    model = ForceModel.load(args.model)
    ds = load_dataset(args.dataset)
    trained_on = model.metadata_.get('dataset', {}).get('sha256')
    if trained_on and trained_on == ds.sha256():
        print('note: this is the dataset the model was trained on (its train and test parts);'
              ' the test RMSE stored in the model is the honest figure')
    pred = model.predict(ds.X)
    err = np.abs(pred - ds.Y)
    e = rmse(pred, ds.Y)
    print(f'{"output":<6} {"RMSE N":>9} {"max N":>9} {"range N":>9}')
    for o, name in enumerate(OUTPUT_NAMES):
        span = float(np.ptp(ds.Y[:, o]))
        print(f'{name:<6} {e[o]:>9.5f} {err[:, o].max():>9.5f} {span:>9.4f}')
    return 0

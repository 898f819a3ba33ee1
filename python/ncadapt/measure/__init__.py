"""Measured points of a surface and their deviations along the normals.

A measurement is a nominal point p with its unit outward normal n (pointing away from material)
and either the measured point m or the deviation e directly. The deviation is

    e = (m − p) · n                      e > 0: material left over

(the sign convention of every ncadapt deviation). When the measured points are probe-tip centres, the surface point is
the centre moved back along the normal by the tip radius: e = (m − p) · n − r.

Readers (:func:`read` picks one from the file's contents):

- CSV with a header: ``x,y,z,i,j,k,mx,my,mz`` or ``x,y,z,i,j,k,dev``, optional ``id``;
- DMIS output: ``F(name)=FEAT/POINT,CART,x,y,z,i,j,k`` nominals and the ``FA(name)=FEAT/POINT,CART,…``
  actuals, ``$`` continuing a statement on the next line;
- PC-DMIS XYZIJK text: ``x y z i j k`` rows (nominal and normal) followed by a ``dev`` column or by
  ``mx my mz``;
- QIF 3 results: point features with nominal ``Location``/``Normal`` and measured ``Location``.

With a CAD nominal (:func:`against_cad`), actual points (:func:`read_actuals`: CSV ``x,y,z``,
DMIS ``FA(label)=FEAT/POINT`` outputs, QIF 3 ``PointFeatureActual`` and ``MeasuredPointSet``) are
projected onto the part's faces and the deviation is taken along the face's outward normal; a file
with nominals of its own gives its actual points (nominal + deviation × normal when it has no
actual coordinates) and its nominals must lie on the CAD. Before that the points may
be aligned to the part (:class:`Alignment`): a least-squares best fit on the faces
(:func:`align_to_cad`) or an RPS / 3-2-1 alignment on datum points and features (:func:`read_datums`,
:func:`align_datums`; the features fitted by least squares with :func:`fit_feature`).

Nothing is guessed: NaN, zero or non-unit normals (|n| off 1 by more than 1e-3), duplicate ids and
mismatched nominal/measured sets are errors naming the file and line.
"""

from __future__ import annotations

from ._actuals import Actuals, read_actuals, read_csv_actuals, read_dmis_actuals, read_qif_actuals
from ._align import DOF, Alignment, Datum, DatumResidual, align_datums, align_to_cad, read_datums, rotation_matrix
from ._cad import CadProjection, against_cad, project_on_cad
from ._core import Measurements, from_arrays
from ._fit import FeatureFit, fit_feature
from ._readers import read, read_csv, read_dmis, read_qif, read_xyzijk

__all__ = [
    "DOF",
    "Actuals",
    "Alignment",
    "CadProjection",
    "Datum",
    "DatumResidual",
    "FeatureFit",
    "Measurements",
    "against_cad",
    "align_datums",
    "align_to_cad",
    "fit_feature",
    "from_arrays",
    "project_on_cad",
    "read",
    "read_actuals",
    "read_csv_actuals",
    "read_dmis_actuals",
    "read_qif_actuals",
    "read_datums",
    "read_csv",
    "read_dmis",
    "read_qif",
    "read_xyzijk",
    "rotation_matrix",
]

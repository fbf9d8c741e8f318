"""Reading a Dagster run's result by asset: the PWA chain's assets share one node."""

import dagster as dg


def materialization(result, asset: str) -> dg.AssetMaterialization:
    """The (first) materialisation of ``asset`` in ``result``."""
    key = dg.AssetKey(asset)
    return next(e.materialization for e in result.get_asset_materialization_events()
                if e.asset_key == key)


def holding(assets, names) -> list:
    """The asset definitions among ``assets`` that hold any of the assets ``names`` (to
    materialise with ``selection=names`` and only their resources)."""
    return [a for a in assets if {k.to_user_string() for k in a.keys} & set(names)]

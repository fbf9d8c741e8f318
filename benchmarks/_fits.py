"""The default fits that several timing benchmarks repeat, named ``case:seed`` or ``robot``."""


def default_fit(fit: str):
    """The default estimator and training record of a fit named ``case:seed`` (a case of
    ``benchmarks.robustness`` at a seed) or ``robot`` (the default set on the KUKA training
    record): ``(estimator, u, y)``. Imports inside, so that a worker can pair this checkout's
    benchmarks with an earlier commit's package."""
    from sklearn.base import clone

    if fit == "robot":
        from pwa_pipeline import load_kuka
        from pwa_pipeline.config import HParamsFile

        robot = load_kuka()
        return (clone(HParamsFile().configuration("default", "kuka_robot").pwa),
                robot.u_train, robot.y_train)
    from benchmarks.robustness import CASES, paper_system, random_system
    from pwa_pipeline import PWARX

    name, seed = fit.split(":")
    case = CASES[name]
    system = (paper_system() if case.system is None
              else random_system(int(seed), **case.system, hold=case.hold))
    record = system.record(case.n, int(seed), case.snr_db, case.hold)
    return PWARX(na=system.na, nb=system.nb), record.u, record.y

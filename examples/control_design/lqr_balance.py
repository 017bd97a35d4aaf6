"""The former name of one_foot_lqr.py (renamed when examples/controllers/ had a standing
lqr_balance.py too: two files of one name, issue 40). Kept for one release: importing or running it
warns and does what one_foot_lqr.py does."""

from one_foot_lqr import (  # noqa: F401 - the names the former module had
    Design,
    LqrLoop,
    Run,
    design,
    figure,
    largest_push,
    lqr,
    main,
    noise_std,
    one_foot_pose,
    run,
    setup,
    smoothed_noise,
    survives,
)

from mexone.errors import warn_renamed

warn_renamed("examples/control_design/lqr_balance.py", "one_foot_lqr.py")

if __name__ == "__main__":
    main()

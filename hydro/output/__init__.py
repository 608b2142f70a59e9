"""Hydro output and viewers: snapshot files, the snapshot data contract, VTKHDF export,
figures and the yt loader."""

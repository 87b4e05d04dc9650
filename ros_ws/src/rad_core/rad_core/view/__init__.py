"""Pictures and progress: PNG/APNG renders, Rerun views, the terminal progress bar."""

"""The job kinds (params.py: their one definition) and their runs side by side: convert, analyze, refine."""

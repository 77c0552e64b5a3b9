"""objsearch.replay"""

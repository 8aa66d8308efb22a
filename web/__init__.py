"""What a browser sees: leaderboard pages, plots and the 3D replay."""

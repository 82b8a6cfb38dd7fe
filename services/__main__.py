from services.cli import app

if __name__ == "__main__":  # importing it (as a tool or a spawned process may) starts nothing
    app(prog_name="spacemap")

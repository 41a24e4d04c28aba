/// <reference types="vitest/config" />
import { defineConfig } from "vite";

// Preact's JSX through the bundler's own transform (no framework plugin needed).
export default defineConfig({
  esbuild: { jsx: "automatic", jsxImportSource: "preact" },
  oxc: { jsx: { runtime: "automatic", importSource: "preact" } },
  build: { outDir: "dist", emptyOutDir: true, sourcemap: false },
  // unit tests of the pure modules (npm test; tests/frontend/test_vitest.py runs them in make test)
  test: { include: ["src/**/*.test.ts"], environment: "node" },
});

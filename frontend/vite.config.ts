import { defineConfig } from "vite";

// Preact's JSX through the bundler's own transform (no framework plugin needed).
export default defineConfig({
  esbuild: { jsx: "automatic", jsxImportSource: "preact" },
  oxc: { jsx: { runtime: "automatic", importSource: "preact" } },
  build: { outDir: "dist", emptyOutDir: true, sourcemap: false },
});

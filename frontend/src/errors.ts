// Errors through context: the page's banner (main.tsx) provides `report`; every panel
// takes it with useReportError() instead of an onError prop handed down to it.
import { createContext } from "preact";
import { useContext } from "preact/hooks";

/** Show a message in the page's error banner; null clears it. */
export type ReportError = (message: string | null) => void;

// Outside a provider (a panel rendered on its own) errors go to the console.
export const ErrorContext = createContext<ReportError>((message) => {
  if (message !== null) console.error(message);
});

export function useReportError(): ReportError {
  return useContext(ErrorContext);
}

/** An exception as the text the banner shows. */
export function errorText(e: unknown): string {
  return e instanceof Error ? e.message : String(e);
}

/** A user's command: its result with the banner cleared, or undefined with its error shown. */
export async function reported<T>(report: ReportError, command: () => Promise<T>): Promise<T | undefined> {
  try {
    const result = await command();
    report(null);
    return result;
  } catch (e) {
    report(errorText(e));
    return undefined;
  }
}

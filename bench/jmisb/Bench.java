// jMISB's KLV parser on a file of raw KLV (bench/bench_klv.py's peer): parses every packet of the
// file `reps` times after a JIT warm-up and prints "<messages> <best seconds> <ST 0601 values>".
import java.nio.file.Files;
import java.nio.file.Paths;
import java.util.List;
import org.jmisb.api.klv.IMisbMessage;
import org.jmisb.api.klv.KlvParser;
import org.jmisb.api.klv.st0601.UasDatalinkMessage;

public class Bench {
    public static void main(String[] args) throws Exception {
        byte[] data = Files.readAllBytes(Paths.get(args[0]));
        int reps = Integer.parseInt(args[1]);
        List<IMisbMessage> out = null;
        for (int w = 0; w < 5; w++) {
            out = KlvParser.parseBytes(data);
        }
        long best = Long.MAX_VALUE;
        for (int r = 0; r < reps; r++) {
            long t0 = System.nanoTime();
            out = KlvParser.parseBytes(data);
            best = Math.min(best, System.nanoTime() - t0);
        }
        long values = 0;
        for (IMisbMessage m : out) {
            if (m instanceof UasDatalinkMessage) {
                values += ((UasDatalinkMessage) m).getIdentifiers().size();
            }
        }
        System.out.println(out.size() + " " + (best / 1e9) + " " + values);
    }
}
